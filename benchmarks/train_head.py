"""Heads the benchmarks need and the package does not ship, trained on one core in resumable pieces.

    .venv/bin/python -m benchmarks.train_head flow-tp32 --data outputs/data/pusht_400ep_seed0_noise0-5.npz

Each head is trained like a shipped one (same demonstrations, features, recipe and seed) with one
change, named in :data:`HEADS`. The run is a step budget written to ``TRAINED_HEADS/<dir>`` (never
the repository) by :func:`benchmarks.resumable.train_steps`: a stopped machine loses at most a
minute, and the same command continues with the same bytes as an uninterrupted run. A finished
head is never overwritten (delete it first).

- ``flow-tp32``: the flow head of chapter 10 with a longer chunk, Tp = 32 (usable horizon
  H = Tp - To + 1 = 31), so that chapter 11's real-time chunking has a soft region at d = 4-8
  (it needs d <= s <= H - d). Departure from the shipped ``pusht_flow_state``: one cosine schedule
  over all 19259 steps instead of its two phases (8510 steps, then 10749 warm-started).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchmarks.bench_chunk_ablation import DATA
from benchmarks.resumable import cache_dir

TRAINED_HEADS = cache_dir("heads")
"""Where heads that are not shipped live (bench_latency and bench_rtc_regime look here)."""
HEADS = {  # name -> folder, policy type, config fields, step budget (the shipped head's total), seed
    "flow-tp32": {"dir": "pusht_flow_state_tp32", "policy": "flow", "fields": {"horizon": 32}, "steps": 19259,
                  "seed": 0},
}
COMMAND = ".venv/bin/python -m benchmarks.train_head"


def command(name: str) -> str:
    """The command that trains the head ``name`` (recorded in the notes of the rows that use it)."""
    return (f"{COMMAND} {name} (data: coursekit collect pusht --episodes 400 --seed 0 --action-noise 0,5; "
            f"features pusht_keypoints, recipe cpu, {HEADS[name]['steps']} steps, seed {HEADS[name]['seed']})")


def train_head(name: str, data: Path, threads: int = 1, progress: bool = True) -> Path:
    """Train (or continue training) the head ``name`` on the demonstrations ``data``; returns its folder."""
    from benchmarks.resumable import state_path, train_steps
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.policies import make_policy

    spec = HEADS[name]
    out = TRAINED_HEADS / spec["dir"]
    state = state_path(out)
    if out.exists() and not state.is_file():  # with a state beside it, a kill hit the final write: finish the run
        raise SystemExit(f"{out} exists: {name} is trained (delete the folder to train it again)")
    if not data.is_file():
        raise SystemExit(f"--data {data} does not exist (make it with: coursekit collect pusht --episodes 400 --seed 0 "
                         f"--action-noise 0,5 --out {data})")
    dataset = EpisodeDataset.load(data)
    policy, batches, recipe = make_policy(spec["policy"], dataset, features="pusht_keypoints", recipe="cpu",
                                          seed=spec["seed"], **spec["fields"])
    print(f"{name}: {spec['policy']} policy, {spec['fields']}, {spec['steps']} steps"
          f"{' (resuming ' + str(state) + ')' if state.is_file() else ''} -> {out}", flush=True)
    train_steps(policy, batches, recipe, out, spec["steps"], spec["seed"], threads, dataset.meta, progress)
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("head", choices=sorted(HEADS), help="the head to train")
    parser.add_argument("--data", type=Path, default=DATA, help=f"the shipped models' demonstrations (default {DATA})")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (one run per core)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = parser.parse_args(argv)
    print(f"wrote {train_head(args.head, args.data, args.threads, not args.no_progress)}")


if __name__ == "__main__":
    main()
