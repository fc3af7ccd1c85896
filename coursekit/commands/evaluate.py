"""``coursekit eval CKPT``: evaluate a checkpoint on held-out seeds.

PushT policies by the Diffusion Policy protocol (mean-of-max score, success rate); policies on
ALOHA features (ACT, or DP trained on the arm pair) on the task their demonstrations came from,
with the published stage rates and the strict final-state success.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "evaluate a policy checkpoint on held-out seeds (PushT score/success, ALOHA stages/strict success)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", type=Path, help="checkpoint directory (from `coursekit train`)")
    parser.add_argument("--episodes", type=int, default=50, help="held-out episodes (default 50)")
    parser.add_argument("--seed-start", type=int, default=None, help="first reset seed (default 100000; episode i uses start + i)")
    parser.add_argument("--max-steps", type=int, default=None, help="steps per episode (default 300 PushT, 400 ALOHA)")
    parser.add_argument("--sampler", choices=["ddim", "ddpm", "euler", "midpoint"], default=None,
                        help="sampler (default: the checkpoint's): ddim/ddpm for diffusion, euler/midpoint for flow")
    parser.add_argument("--steps", type=int, default=None,
                        help="denoising / integration steps (default: 10 for DDIM and flow, 100 for DDPM)")
    parser.add_argument("--ddim-spacing", choices=["leading", "trailing"], default=None,
                        help="DDIM timesteps: leading (90, 80, ..., 0) or trailing (99, 89, ..., 9) (default: the checkpoint's)")
    parser.add_argument("--n-action-steps", type=int, default=None, help="override Ta, actions executed per chunk")
    parser.add_argument("--no-ensembling", action="store_true",
                        help="ACT: execute chunks by receding horizon instead of temporal ensembling")
    parser.add_argument("--ensemble-decay", type=float, default=None, help="ACT: m in w_i = exp(-m i) (default: the checkpoint's)")
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

    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads must be >= 1, got {args.threads}")
        torch.set_num_threads(args.threads)
    info = read_checkpoint_info(args.checkpoint)
    policy = load_checkpoint(args.checkpoint, device=args.device)
    seeds = heldout_seeds(args.episodes, EVAL_SEED_START if args.seed_start is None else args.seed_start)
    c = policy.config
    if args.sampler is not None:
        kinds = {"flow": ("euler", "midpoint"), "diffusion": ("ddim", "ddpm")}.get(info.get("policy_type"), ())
        if args.sampler not in kinds:
            raise ValueError(f"--sampler {args.sampler} does not apply to a {info.get('policy_type')!r} checkpoint; "
                             f"expected one of {list(kinds)}")
    if args.no_ensembling or args.ensemble_decay is not None:
        if not hasattr(c, "temporal_ensembling"):
            raise ValueError(f"--no-ensembling/--ensemble-decay apply to ACT checkpoints, this one is {info.get('policy_type')!r}")
        if args.ensemble_decay is not None and not args.ensemble_decay >= 0:
            raise ValueError(f"--ensemble-decay must be >= 0, got {args.ensemble_decay}")
        c.temporal_ensembling = not args.no_ensembling
        c.ensemble_decay = c.ensemble_decay if args.ensemble_decay is None else args.ensemble_decay
    if args.ddim_spacing is not None:
        if not hasattr(c, "ddim_timestep_spacing"):
            raise ValueError(f"--ddim-spacing applies to diffusion checkpoints, this one is {info.get('policy_type')!r}")
        c.ddim_timestep_spacing = args.ddim_spacing
    if str(getattr(c, "features", "")).startswith("aloha"):
        return _run_aloha(args, policy, info, seeds)
    factory = None
    if args.n_action_steps is not None:
        if not 1 <= args.n_action_steps <= c.horizon - c.n_obs_steps + 1:
            raise ValueError(f"--n-action-steps must be in [1, Tp - To + 1 = {c.horizon - c.n_obs_steps + 1}], got {args.n_action_steps}")
        factory = lambda pc: RecedingHorizon(pc, c.n_obs_steps, args.n_action_steps)  # noqa: E731
    result = evaluate_pusht(policy, seeds=seeds, max_steps=args.max_steps or 300, sampler=args.sampler,
                            num_inference_steps=args.steps, seed=args.seed, executor_factory=factory,
                            dataset_meta=info.get("dataset"), progress=not args.no_progress)
    summary = {"checkpoint": str(args.checkpoint), **result.summary()}
    if args.n_action_steps is not None:
        summary["n_action_steps"] = args.n_action_steps
    return _report(args, summary)


def _run_aloha(args: argparse.Namespace, policy, info: dict, seeds: list[int]) -> int:
    from coursekit.evaluate_aloha import ALOHA_TASKS, evaluate_aloha

    task = (info.get("dataset") or {}).get("task")
    if task not in ALOHA_TASKS:
        raise ValueError(f"checkpoint {str(args.checkpoint)!r} uses ALOHA features but its dataset meta names task "
                         f"{task!r}; expected one of {sorted(ALOHA_TASKS)}")
    result = evaluate_aloha(policy, task, seeds=seeds, max_steps=args.max_steps or 400,
                            dataset_meta=info.get("dataset"), progress=not args.no_progress)
    summary = {"checkpoint": str(args.checkpoint), "task": task, "episodes": len(seeds),
               "stage_rates": result.info["stage_rates"], "strict_success_rate": result.info["strict_success_rate"],
               "temporal_ensembling": getattr(policy.config, "temporal_ensembling", None)}
    return _report(args, summary)


def _report(args: argparse.Namespace, summary: dict) -> int:
    from coursekit.io import atomic_write_text

    text = json.dumps(summary, indent=1)
    print(text)
    if args.json is not None:
        atomic_write_text(args.json, text + "\n")
    return 0
