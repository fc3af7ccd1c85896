"""How multimodal are the course's PushT demonstrations? The two-way fraction of each data set.

    .venv/bin/python -m benchmarks.bench_multimodality                    # both default data sets
    .venv/bin/python -m benchmarks.bench_multimodality --data A.npz B.npz --no-record

The definition is :mod:`coursekit.data.multimodality` (a state is two-way when the nearest rows
of at least six demonstrations head more than 90 degrees apart, with at least a quarter of the
moving ones in the minority). Defaults: the scripted planner's 400 DART 0/5 demonstrations (what
the shipped PushT checkpoints train on) and the same resets demonstrated with a person's variety
(``coursekit collect pusht --episodes 400 --action-noise 0,5 --style person``). The interval is a
bootstrap over demonstrations (95 %); n is the number of supported query states.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchmarks.resumable import cache_dir

SECTION = "Multimodality of the demonstrations (PushT)"
DATA_DIR = cache_dir("data")
"""The data sets the long benchmarks share live outside the repository (they outlast a work tree)."""
DEFAULT_DATA = (DATA_DIR / "pusht_400ep_seed0_noise0-5.npz", DATA_DIR / "pusht_400ep_seed0_noise0-5_person.npz")
COLLECT = {"pusht_400ep_seed0_noise0-5.npz": "coursekit collect pusht --episodes 400 --seed 0 --action-noise 0,5",
           "pusht_400ep_seed0_noise0-5_person.npz":
               "coursekit collect pusht --episodes 400 --seed 0 --action-noise 0,5 --style person"}


def label(meta: dict) -> str:
    """'scripted planner' or 'person-like' demonstrations, with their count and noise."""
    kind = "person-like" if meta.get("expert_style") else "scripted planner"
    noise = ",".join(f"{v:g}" for v in meta.get("action_noise", [0.0]))
    return f"{kind}, {meta.get('n_episodes', '?')} demonstrations, DART {noise} px"


def main(argv: list[str] | None = None) -> int:
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.data.multimodality import MultimodalityConfig, two_way_fraction

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, nargs="+", default=list(DEFAULT_DATA))
    parser.add_argument("--queries", type=int, default=2000, help="query states per data set")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")
    args = parser.parse_args(argv)
    for path in args.data:
        if not path.exists():
            hint = COLLECT.get(path.name, "coursekit collect pusht ...")
            raise SystemExit(f"--data {path} does not exist (make it with: {hint} --out {path})")
    config = MultimodalityConfig(n_queries=args.queries)
    for path in args.data:
        dataset = EpisodeDataset.load(path)
        m = two_way_fraction(dataset, config)
        name = f"two-way fraction of states, {label(dataset.meta)}"
        note = (f"{m.n_supported} of {m.n_queries} query states supported (>= {config.min_episodes} demonstrations "
                f"within {config.radius:g} px); 95 % bootstrap over demonstrations; data: {COLLECT.get(path.name, path.name)}")
        print(f"{name}: {m.fraction:.3f} [{m.lo:.3f}, {m.hi:.3f}] (n={m.n_supported}); {note}")
        if not args.no_record:
            from benchmarks.results import record

            shown = f"~/.cache/coursekit/data/{path.name}" if path.parent == DATA_DIR else str(path)
            command = f".venv/bin/python -m benchmarks.bench_multimodality --data {shown} --queries {args.queries}"
            record(SECTION, name, m.fraction, "", command, note=note, interval=(m.lo, m.hi), n=m.n_supported)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
