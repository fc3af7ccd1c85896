"""``coursekit collect TASK``: generate scripted demonstrations and write a dataset file."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from coursekit.commands._args import MAX_SEED, int_in, output_path, seed_int
from coursekit.tasks.registry import TASKS, get_task, task_names  # plain data: `coursekit --help` stays instant

HELP = f"generate scripted demonstrations of a task ({', '.join(task_names())}) into a dataset file"
MAX_EPISODES = 100_000
"""More demonstrations cannot be meant: the experts run ~2 PushT episodes/s, so 100000 is already a day's work."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    with_expert = [t for t in TASKS.values() if t.expert is not None]
    parser.add_argument("task", choices=[n for n in task_names(aliases=True) if get_task(n).expert is not None],
                        help="which task's scripted expert to run (a task name or an alias such as aloha-cube)")
    parser.add_argument("--episodes", type=int_in(1, MAX_EPISODES), default=None,
                        help=f"number of demonstrations, at most {MAX_EPISODES} (default: " + ", ".join(
                            f"{t.demo_episodes} {t.name}" for t in with_expert) + ")")
    parser.add_argument("--seed", type=seed_int, default=0, help="seed of the first episode; episode i uses seed + i")
    parser.add_argument("--out", type=output_path, default=None, help="output .npz (default: outputs/data/<task>_<episodes>ep_seed<seed>[_noise<levels>][_person].npz)")
    parser.add_argument("--action-noise", default=None,
                        help="pusht only: DART execution noise in px (the env runs the expert's target plus Gaussian "
                             "noise, the file keeps the clean target); a comma list is cycled over episodes, "
                             "e.g. 0,10 alternates clean and noisy demonstrations (default 0)")
    parser.add_argument("--style", choices=["scripted", "person"], default=None,
                        help="pusht only: scripted (default) = the planner's own demonstrations; person = with a "
                             "person's variety (a random pick among equally good pushes at every re-plan, the long "
                             "way round more often, a pace per episode, pauses)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing dataset at --out (atomically: the old file stays until the new one is complete)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run(args: argparse.Namespace) -> int:
    from coursekit.data.episodes import dataset_foreign
    from coursekit.outputs import claim_output

    task = get_task(args.task)
    episodes = args.episodes if args.episodes is not None else task.demo_episodes
    if args.seed > MAX_SEED - (episodes - 1):
        raise ValueError(f"--seed must be in [0, {MAX_SEED - (episodes - 1)}] (episode i uses seed + i), got {args.seed}")
    extra, tag = {}, ""
    if args.action_noise is not None:
        if "action_noise" not in task.expert_options:
            takers = " / ".join(t.name for t in TASKS.values() if "action_noise" in t.expert_options)
            raise ValueError(f"--action-noise is for the {takers} expert only, not {args.task!r}")
        from coursekit.experts.pusht_planner import noise_tag, parse_action_noise

        extra["action_noise"] = parse_action_noise(args.action_noise)
        tag = noise_tag(extra["action_noise"])
    if args.style is not None:
        if args.task != "pusht":
            raise ValueError(f"--style is for the pusht expert only, not {args.task!r}")
        from coursekit.experts.pusht_person import STYLES

        extra["style"] = STYLES[args.style]
        tag += "" if args.style == "scripted" else f"_{args.style}"
    out = args.out or Path("outputs/data") / f"{args.task}_{episodes}ep_seed{args.seed}{tag}.npz"
    with claim_output(out, what="coursekit dataset", foreign=dataset_foreign, directory=False,
                      overwrite=args.overwrite) as lock:
        for leftover in lock.swept:
            print(f"removed {str(leftover)!r}, left by an interrupted earlier run", file=sys.stderr)
        start = time.perf_counter()
        dataset = task.collect(episodes, args.seed, progress=not args.no_progress, **extra)
        dataset.save(out, lock=lock)
    seconds = time.perf_counter() - start
    print(f"wrote {out}: {dataset.n_episodes} episodes, {dataset.n_steps} steps in {seconds:.1f} s")
    return 0
