"""Keep finished evaluations in the repository, so that a sweep can span machines whose caches start empty.

    .venv/bin/python -m benchmarks.ledger            # copy new evaluations from the cache into benchmarks/ledger/
    .venv/bin/python -m benchmarks.ledger --check    # only say what would be copied, and any that disagree

The long sweeps (``bench_act_chunks``: 15 runs; ``bench_chunk_ablation`` on person-like data: 9 runs)
take longer than a machine keeps its cache. A run's checkpoint stays in the cache (megabytes, and
retrainable from its seed); its evaluation files (``eval_*.json``: the protocol seeds and each one's
outcome, a few kilobytes) are what a row is computed from, so they are kept here and read first
(``benchmarks.resumable.evaluation_file``). Only evaluations of finished runs are kept; a kept file is
never overwritten, and one that differs from the cache's copy is reported, not replaced.
"""

from __future__ import annotations

import argparse
import filecmp
from pathlib import Path

from benchmarks.resumable import CACHE_ROOT, LEDGER, is_trained, kept_file
from coursekit.atomic import atomic_write_text

BENCHES = ("act_chunks", "chunk_ablation")
"""The caches whose runs' evaluations are kept (``cache_dir`` names of the benchmarks that train sweeps)."""


def pending(cache_root: Path = CACHE_ROOT, ledger: Path = LEDGER) -> tuple[list[tuple[Path, Path]], list[Path]]:
    """(cache file, ledger file) pairs not kept yet, and the kept files whose cache copy differs."""
    new, differ = [], []
    for bench in BENCHES:
        for run in sorted(p for p in (cache_root / bench).glob("*") if p.is_dir() and is_trained(p)):
            for src in sorted(run.glob("eval_*.json")):
                dst = kept_file(run, src.name, ledger)
                if not dst.exists():
                    new.append((src, dst))
                elif not filecmp.cmp(src, dst, shallow=False):
                    differ.append(dst)
    return new, differ


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="copy nothing; list what would be kept")
    parser.add_argument("--cache", type=Path, default=CACHE_ROOT, help="the benchmarks' cache root")
    parser.add_argument("--ledger", type=Path, default=LEDGER, help="where evaluations are kept")
    args = parser.parse_args(argv)
    new, differ = pending(args.cache, args.ledger)
    for src, dst in new:
        print(f"{'would keep' if args.check else 'kept'} {dst.relative_to(args.ledger)}")
        if not args.check:
            dst.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(dst, src.read_text())  # a killed copy leaves no half-written kept file
    for dst in differ:
        print(f"differs from the cache, left as it is: {dst}")
    print(f"{len(new)} new evaluation file(s){' (not copied: --check)' if args.check and new else ''}; "
          f"{len(differ)} disagreeing")
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
