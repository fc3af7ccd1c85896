"""``coursekit eval CKPT``: evaluate a PushT checkpoint by the paper's protocol."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "evaluate a PushT policy checkpoint: mean-of-max score and success rate on held-out seeds"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", type=Path, help="checkpoint directory (from `coursekit train`)")
    parser.add_argument("--episodes", type=int, default=50, help="held-out episodes (default 50)")
    parser.add_argument("--seed-start", type=int, default=None, help="first reset seed (default 100000; episode i uses start + i)")
    parser.add_argument("--max-steps", type=int, default=300, help="steps per episode (default 300)")
    parser.add_argument("--sampler", choices=["ddim", "ddpm"], default=None, help="diffusion sampler (default: the checkpoint's)")
    parser.add_argument("--steps", type=int, default=None, help="denoising steps (default: 10 for DDIM, 100 for DDPM)")
    parser.add_argument("--n-action-steps", type=int, default=None, help="override Ta, actions executed per chunk")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sampler noise (default 0)")
    parser.add_argument("--device", default="auto", help="auto, cpu, cuda, mps (default auto)")
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--json", type=Path, default=None, help="also write the summary to this JSON file")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run(args: argparse.Namespace) -> int:
    import torch

    from coursekit.checkpoint import load_checkpoint, read_checkpoint_info
    from coursekit.evaluate import EVAL_SEED_START, evaluate_pusht, heldout_seeds
    from coursekit.execution.receding import RecedingHorizon
    from coursekit.io import atomic_write_text

    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads must be >= 1, got {args.threads}")
        torch.set_num_threads(args.threads)
    info = read_checkpoint_info(args.checkpoint)
    policy = load_checkpoint(args.checkpoint, device=args.device)
    seeds = heldout_seeds(args.episodes, EVAL_SEED_START if args.seed_start is None else args.seed_start)
    factory = None
    if args.n_action_steps is not None:
        c = policy.config
        if not 1 <= args.n_action_steps <= c.horizon - c.n_obs_steps + 1:
            raise ValueError(f"--n-action-steps must be in [1, Tp - To + 1 = {c.horizon - c.n_obs_steps + 1}], got {args.n_action_steps}")
        factory = lambda pc: RecedingHorizon(pc, c.n_obs_steps, args.n_action_steps)  # noqa: E731
    result = evaluate_pusht(policy, seeds=seeds, max_steps=args.max_steps, sampler=args.sampler,
                            num_inference_steps=args.steps, seed=args.seed, executor_factory=factory,
                            dataset_meta=info.get("dataset"), progress=not args.no_progress)
    summary = {"checkpoint": str(args.checkpoint), **result.summary()}
    if args.n_action_steps is not None:
        summary["n_action_steps"] = args.n_action_steps
    text = json.dumps(summary, indent=1)
    print(text)
    if args.json is not None:
        atomic_write_text(args.json, text + "\n")
    return 0
