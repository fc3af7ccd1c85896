"""``coursekit collect TASK``: generate scripted demonstrations and write a dataset file."""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

from coursekit.commands._args import MAX_SEED, int_in, seed_int

HELP = "generate scripted demonstrations (pusht, aloha-cube, aloha-insertion) into a dataset file"

# task -> "module:function" with signature (n_episodes, seed, progress=True) -> EpisodeDataset
TASKS: dict[str, str] = {
    "pusht": "coursekit.experts.pusht_planner:collect_dataset",
    "aloha-cube": "coursekit.experts.aloha_scripted:collect_transfer_cube",
    "aloha-insertion": "coursekit.experts.aloha_scripted:collect_insertion",
}
DEFAULT_EPISODES = {"pusht": 200, "aloha-cube": 50, "aloha-insertion": 50}
MAX_EPISODES = 100_000
"""More demonstrations cannot be meant: the experts run ~2 PushT episodes/s, so 100000 is already a day's work."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("task", choices=sorted(TASKS), help="which task's scripted expert to run")
    parser.add_argument("--episodes", type=int_in(1, MAX_EPISODES), default=None,
                        help=f"number of demonstrations, at most {MAX_EPISODES} (default: 200 PushT, 50 ALOHA)")
    parser.add_argument("--seed", type=seed_int, default=0, help="seed of the first episode; episode i uses seed + i")
    parser.add_argument("--out", type=Path, default=None, help="output .npz (default: outputs/data/<task>_<episodes>ep_seed<seed>[_noise<levels>].npz)")
    parser.add_argument("--action-noise", default=None,
                        help="pusht only: DART execution noise in px (the env runs the expert's target plus Gaussian "
                             "noise, the file keeps the clean target); a comma list is cycled over episodes, "
                             "e.g. 0,10 alternates clean and noisy demonstrations (default 0)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing dataset at --out (atomically: the old file stays until the new one is complete)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run(args: argparse.Namespace) -> int:
    from coursekit.data.episodes import is_dataset_file
    from coursekit.outputs import check_output, clean_leftovers

    episodes = args.episodes if args.episodes is not None else DEFAULT_EPISODES[args.task]
    if args.seed > MAX_SEED - (episodes - 1):
        raise ValueError(f"--seed must be in [0, {MAX_SEED - (episodes - 1)}] (episode i uses seed + i), got {args.seed}")
    module_name, func_name = TASKS[args.task].split(":")
    collect = getattr(importlib.import_module(module_name), func_name)
    extra, tag = {}, ""
    if args.action_noise is not None:
        if args.task != "pusht":
            raise ValueError(f"--action-noise is for the pusht expert only, not {args.task!r}")
        from coursekit.experts.pusht_planner import noise_tag, parse_action_noise

        extra["action_noise"] = parse_action_noise(args.action_noise)
        tag = noise_tag(extra["action_noise"])
    out = args.out or Path("outputs/data") / f"{args.task}_{episodes}ep_seed{args.seed}{tag}.npz"
    check_output(out, what="coursekit dataset", is_ours=is_dataset_file, directory=False, overwrite=args.overwrite)
    for leftover in clean_leftovers(out):
        print(f"removed {str(leftover)!r}, left by an interrupted earlier run", file=sys.stderr)
    start = time.perf_counter()
    dataset = collect(episodes, args.seed, progress=not args.no_progress, **extra)
    dataset.save(out)
    seconds = time.perf_counter() - start
    print(f"wrote {out}: {dataset.n_episodes} episodes, {dataset.n_steps} steps in {seconds:.1f} s")
    return 0
