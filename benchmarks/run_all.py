"""Run every benchmark in this folder, one after another (``make bench``).

Each ``bench_*.py`` records its own figures into ``benchmarks/results.json`` and the README
table. Some take many minutes (training runs): pass names to run a subset, e.g.
``python -m benchmarks.run_all pusht_env pusht_expert``.
"""

from __future__ import annotations

import runpy
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    names = sorted(p.stem.removeprefix("bench_") for p in HERE.glob("bench_*.py"))
    chosen = argv or names
    unknown = sorted(set(chosen) - set(names))
    if unknown:
        print(f"unknown benchmark(s) {unknown}; available: {names}", file=sys.stderr)
        return 2
    for name in chosen:
        start = time.perf_counter()
        print(f"== benchmarks.bench_{name}", flush=True)
        runpy.run_module(f"benchmarks.bench_{name}", run_name="__main__")
        print(f"== bench_{name} done in {time.perf_counter() - start:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
