"""``coursekit eval CKPT``: evaluate a checkpoint on held-out seeds, and optionally record a replay.

Any policy on the task it was trained for: PushT by the Diffusion Policy protocol (mean-of-max
score, success rate); the arm pair (ACT, or DP / regression on arm-pair features) on the task
its demonstrations came from, with the published stage rates and the strict final-state
success. Evaluation-time changes (--ddim-spacing, --ensemble-decay, --no-ensembling,
--n-action-steps) make a validated copy of the loaded policy; --sampler / --steps are its
sampling options. ``--record DIR`` writes a self-contained meshcat HTML replay of the first
--record-episodes episodes and a PNG grid of their first/last frames with the scores.
"""

from __future__ import annotations

import argparse
import contextlib
import json
from pathlib import Path
from typing import Any

from coursekit.commands._args import MAX_SEED, device, int_in, nonnegative_float, output_path, seed_int, threads
from coursekit.tasks.registry import TASKS  # plain data: `coursekit --help` stays instant

HELP = "evaluate a policy checkpoint on held-out seeds (PushT score/success, ALOHA stages/strict success)"

MAX_EPISODES = 1000
"""Episodes run in lock-step, one environment each; more at once cannot be meant (use several --seed-start)."""
MAX_EPISODE_STEPS = 10_000
"""Step limit per episode: the protocols use 300 (PushT) and 400 (arm pair)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", type=Path, help="checkpoint directory (from `coursekit train`)")
    parser.add_argument("--episodes", type=int_in(1, MAX_EPISODES), default=50,
                        help=f"held-out episodes, at most {MAX_EPISODES} (default 50)")
    parser.add_argument("--seed-start", type=seed_int, default=None, help="first reset seed (default 100000; episode i uses start + i)")
    protocol = ", ".join(f"{t.max_steps} {t.name}" for t in TASKS.values())
    parser.add_argument("--max-steps", type=int_in(1, MAX_EPISODE_STEPS), default=None,
                        help=f"steps per episode (default: the task's protocol, {protocol})")
    parser.add_argument("--sampler", choices=["ddim", "ddpm", "euler", "midpoint"], default=None,
                        help="sampler (default: the checkpoint's): ddim/ddpm for diffusion, euler/midpoint for flow")
    parser.add_argument("--steps", type=int_in(1), default=None,
                        help="denoising / integration steps (default: 10 for DDIM and flow, 100 for DDPM; at most "
                             "the diffusion's T, or 1000 for flow)")
    parser.add_argument("--ddim-spacing", choices=["leading", "trailing"], default=None,
                        help="DDIM timesteps: leading (90, 80, ..., 0) or trailing (99, 89, ..., 9) (default: the checkpoint's)")
    parser.add_argument("--n-action-steps", type=int_in(1), default=None,
                        help="override Ta, actions executed per chunk (ACT: with --no-ensembling)")
    parser.add_argument("--no-ensembling", action="store_true",
                        help="ACT: execute chunks by receding horizon instead of temporal ensembling")
    parser.add_argument("--ensemble-decay", type=nonnegative_float, default=None, help="ACT: m in w_i = exp(-m i) (default: the checkpoint's)")
    parser.add_argument("--seed", type=seed_int, default=0, help="seed of the sampler noise (default 0)")
    parser.add_argument("--device", type=device, default="auto", help="auto, cpu, cuda, mps (default auto)")
    parser.add_argument("--threads", type=threads, default=None, help="torch CPU threads (default: torch's choice)")
    parser.add_argument("--json", type=output_path, default=None,
                        help="also write the summary, with each episode's seed, score, success and steps, to this JSON "
                             "file (an earlier `coursekit eval` summary there is replaced; any other file is refused)")
    parser.add_argument("--record", type=output_path, default=None,
                        help="write a meshcat HTML replay and a PNG grid of first/last frames to this new folder")
    parser.add_argument("--record-episodes", type=int_in(1, MAX_EPISODES), default=None,
                        help="episodes to record with --record, at most --episodes (default 4, or --episodes if fewer)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


# command-line flag -> the config field it changes, in a validated copy of the policy (with_config)
_OVERRIDES = {"ddim_spacing": "ddim_timestep_spacing", "ensemble_decay": "ensemble_decay",
              "n_action_steps": "n_action_steps"}


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    changes = {field: getattr(args, flag) for flag, field in _OVERRIDES.items() if getattr(args, flag) is not None}
    if args.no_ensembling:
        changes["temporal_ensembling"] = False
    return changes


SUMMARY_FORMAT = "coursekit-eval-summary"
"""The ``format`` entry of every summary `coursekit eval --json` writes: what proves a file there is one."""


def eval_summary_foreign(path: Path) -> str | None:
    """None if the (regular) file ``path`` is a summary `coursekit eval --json` wrote, else why not.

    The proof is the summary's ``format`` entry; any other JSON, whatever its keys, is a user's.
    """
    try:
        with open(path, "rb") as fh:
            raw = fh.read(1 << 20)
        data = json.loads(raw.decode("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return "it is not a JSON summary"
    if not isinstance(data, dict) or data.get("format") != SUMMARY_FORMAT:
        return f"it has no \"format\": \"{SUMMARY_FORMAT}\" entry"
    return None


def _claim_outputs(args: argparse.Namespace, stack: contextlib.ExitStack) -> dict[str, Any]:
    """Before any evaluation: --json and --record are checked and locked, the seed range is valid."""
    from coursekit.outputs import claim_output

    if args.seed_start is not None and args.seed_start + args.episodes - 1 > MAX_SEED:
        raise ValueError(f"--seed-start {args.seed_start} + --episodes {args.episodes} runs past the largest seed {MAX_SEED}")
    locks = {}
    if args.json is not None:
        locks["json"] = stack.enter_context(claim_output(
            args.json, what="coursekit evaluation summary", foreign=eval_summary_foreign, directory=False,
            overwrite=True, inputs=[args.checkpoint], flag="--json"))
    if args.record is not None:  # a new or empty folder: write_replay never replaces files
        locks["record"] = stack.enter_context(claim_output(
            args.record, what="new folder", foreign=None, directory=True,
            inputs=[args.checkpoint] + ([args.json] if args.json is not None else []), flag="--record"))
    return locks


def _check_record_episodes(args: argparse.Namespace) -> None:
    """--record-episodes records some of the evaluated episodes: it needs --record and at most --episodes."""
    if args.record_episodes is not None and (args.record is None or args.record_episodes > args.episodes):
        raise ValueError(f"--record-episodes {args.record_episodes} needs --record DIR and at most --episodes "
                         f"({args.episodes})")


def run(args: argparse.Namespace) -> int:
    _check_record_episodes(args)  # a flag error before anything is claimed
    with contextlib.ExitStack() as stack:
        locks = _claim_outputs(args, stack)
        return _evaluate(args, locks)


def _evaluate(args: argparse.Namespace, locks: dict[str, Any]) -> int:
    import torch

    from coursekit.checkpoint import load_checkpoint, read_checkpoint_info
    from coursekit.evaluate.closed_loop import evaluate
    from coursekit.evaluate.result import EVAL_SEED_START, heldout_seeds
    from coursekit.evaluate.tasks import make_adapter, task_of

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    info = read_checkpoint_info(args.checkpoint)
    policy = load_checkpoint(args.checkpoint, device=args.device)
    _check_flags_apply(args, policy)
    seeds = heldout_seeds(args.episodes, EVAL_SEED_START if args.seed_start is None else args.seed_start)
    changes = _overrides(args)
    if changes:
        try:
            policy = policy.with_config(**changes)
        except ValueError as exc:
            raise ValueError(f"{args.checkpoint} holds a {policy.policy_type!r} policy: {exc}") from None
    sampling = {k: v for k, v in (("sampler", args.sampler), ("num_inference_steps", args.steps)) if v is not None}
    task = task_of(policy, info.get("dataset"))
    if args.record is not None and task.replay is None:
        raise ValueError(f"--record {args.record}: task {task.name!r} has no replay drawing (its record's replay is None)")
    adapter = make_adapter(task, policy)
    result = evaluate(policy, adapter, seeds, max_steps=args.max_steps, sampling=sampling, seed=args.seed,
                      dataset_meta=info.get("dataset"), progress=not args.no_progress, record=args.record is not None)
    summary = {"format": SUMMARY_FORMAT, "checkpoint": str(args.checkpoint), **result.summary(),
               "per_episode": _per_episode(adapter, result)}
    if args.record is not None:
        summary["record"] = {k: str(v) for k, v in _write_replay(args, adapter, result, locks["record"]).items()}
    return _report(args, summary, locks.get("json"))


# flag -> (where the policy lists what it accepts, the field it sets)
_FLAGS = {"--sampler": ("sampling_options", "sampler"), "--steps": ("sampling_options", "num_inference_steps"),
          "--ddim-spacing": ("eval_overrides", "ddim_timestep_spacing"),
          "--no-ensembling": ("eval_overrides", "temporal_ensembling"),
          "--ensemble-decay": ("eval_overrides", "ensemble_decay"), "--n-action-steps": ("eval_overrides", "n_action_steps")}


def _check_flags_apply(args: argparse.Namespace, policy: Any) -> None:
    """Refuse (naming flag, value and policy) a flag the loaded policy has no use for, and a bad step count."""
    for flag, (kind, field) in _FLAGS.items():
        value = getattr(args, flag[2:].replace("-", "_"))
        if value not in (None, False) and field not in getattr(policy, kind, ()):
            raise ValueError(f"{flag}{'' if value is True else f' {value}'} does not apply to {str(args.checkpoint)!r}: "
                             f"it holds a {policy.policy_type!r} policy")
    if args.n_action_steps is not None and getattr(policy.config, "temporal_ensembling", False) and not args.no_ensembling:
        raise ValueError(f"--n-action-steps {args.n_action_steps} has no effect on {str(args.checkpoint)!r}: its "
                         f"{policy.policy_type!r} policy executes by temporal ensembling (a new chunk every step); "
                         f"add --no-ensembling to execute {args.n_action_steps} actions per chunk")
    sampling = {k: v for k, v in (("sampler", args.sampler), ("num_inference_steps", args.steps)) if v is not None}
    if sampling:
        try:
            policy.describe_sampling(**sampling)
        except ValueError as exc:
            given = " ".join(f"{flag} {v}" for flag, v in (("--sampler", args.sampler), ("--steps", args.steps)) if v is not None)
            raise ValueError(f"{given}: {exc}") from None


def _per_episode(adapter: Any, result: Any) -> dict[str, list]:
    """Each episode's seed, score and success as the task's protocol judges them, and its steps
    (columns of equal length: for paired comparisons and bootstrap intervals over seeds)."""
    scores, success = adapter.episode_scores(result)
    return {"seed": [int(s) for s in result.seeds], "score": [round(float(v), 6) for v in scores],
            "success": [bool(v) for v in success], "steps": [int(v) for v in result.length]}


def _write_replay(args: argparse.Namespace, adapter: Any, result: Any, lock: Any) -> dict[str, Any]:
    """The first --record-episodes episodes as EpisodeRecordings -> coursekit.viz.replay.write_replay."""
    from coursekit.viz.replay import EpisodeRecording, write_replay

    states = adapter.replay_states(result)  # (N, T+1, S), finished episodes padded with their last state
    scores, success = adapter.episode_scores(result)
    episodes = [EpisodeRecording(seed=result.seeds[i], states=states[i, : int(result.length[i]) + 1],
                                 score=float(scores[i]), success=bool(success[i]))
                for i in range(min(args.record_episodes or 4, len(result.seeds)))]
    return write_replay(args.record, adapter.task, episodes, lock=lock)


def _report(args: argparse.Namespace, summary: dict, lock: Any) -> int:
    from coursekit.atomic import atomic_write_text

    # the screen gets the summary; the per-episode columns go only to the --json file
    print(json.dumps({k: v for k, v in summary.items() if k != "per_episode"}, indent=1))
    if args.json is not None:
        atomic_write_text(args.json, json.dumps(summary, indent=1) + "\n", lock=lock)
    return 0
