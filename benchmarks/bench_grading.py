"""Grading a class: 30 honest students x all registered exercises with ``--jobs 2`` (target < 10 min).

Run: ``.venv/bin/python -m benchmarks.bench_grading``. Each student is a copy of ``solutions/``
(every exercise must score full marks, checked here), graded by ``coursekit grade`` exactly as an
instructor would: one trusted test process per student, one sandboxed worker (bubblewrap where it
works) per exercise. The machine's load average before and after is recorded with the figure,
because the 2 cores may be shared.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import tempfile
import time
from pathlib import Path

from benchmarks.results import record
from coursekit.grading.exercises import EXERCISES, repo_root
from coursekit.grading.grade import grade_submissions

COMMAND = ".venv/bin/python -m benchmarks.bench_grading"
SECTION = "Grading"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--students", type=int, default=30, help="honest students in the class")
    parser.add_argument("--jobs", type=int, default=2, help="students graded in parallel")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")
    args = parser.parse_args(argv)

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory(prefix="coursekit-bench-grading-") as tmp:
        subs = Path(tmp) / "submissions"
        for i in range(args.students):
            shutil.copytree(repo_root() / "solutions", subs / f"student_{i:02d}")
        load_before = os.getloadavg()[0]
        start = time.perf_counter()
        summary = grade_submissions(subs, Path(tmp) / "out", jobs=args.jobs, progress=True)
        seconds = time.perf_counter() - start
        load_after = os.getloadavg()[0]
        rows = list(csv.DictReader((Path(tmp) / "out" / "grades.csv").open()))
    full = sum(e.max_points for e in EXERCISES)
    not_full = [r["student"] for r in rows if float(r["total"]) != full]
    mode = "bubblewrap" if summary.mode == "bwrap" else "NOT isolated (no bwrap)"
    note = (f"{args.students} students x {len(EXERCISES)} exercises, --jobs {args.jobs}, {mode}; "
            f"load average {load_before:.1f} before / {load_after:.1f} after on {os.cpu_count()} cores")
    print(f"graded in {seconds:.0f} s ({seconds / args.students:.1f} s per student); {note}")
    if not_full:
        raise SystemExit(f"honest students below full marks: {not_full}")
    if not args.no_record:
        record(SECTION, f"class of {args.students} x {len(EXERCISES)} exercises, --jobs {args.jobs}",
               round(seconds / 60, 1), "min", COMMAND, target="< 10 min", note=note)


if __name__ == "__main__":
    main()
