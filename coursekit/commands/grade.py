"""``coursekit grade SUBMISSIONS_DIR --out DIR``: grade every submission in a sandboxed subprocess."""

from __future__ import annotations

import argparse
from pathlib import Path

from coursekit.commands._args import int_in, positive_float, positive_int

HELP = "grade a folder of submissions (copies or zips of exercises/): class CSV, Gradescope JSON, feedback"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("submissions", type=Path, nargs="?", help="folder with one sub-folder or .zip per student")
    parser.add_argument("--out", type=Path, help="where grades.csv and <student>/results.json, feedback.md go")
    parser.add_argument("--exercise", action="append", default=None, metavar="ID",
                        help="grade only this exercise (repeatable; default: all registered)")
    parser.add_argument("--jobs", type=positive_int, default=1, help="submissions graded in parallel (one subprocess each)")
    parser.add_argument("--timeout", type=positive_float, default=120.0, help="wall-clock limit per student x exercise, seconds")
    parser.add_argument("--test-timeout", type=positive_float, default=10.0, help="limit per test, seconds")
    parser.add_argument("--memory-mb", type=int_in(256), default=2048, help="address-space cap per subprocess, MiB")
    parser.add_argument("--disk-mb", type=positive_int, default=64, help="size of each worker's private tmpfs (with bubblewrap), MiB")
    parser.add_argument("--hidden-tests", type=Path, default=None, metavar="DIR",
                        help="instructor-only tests (count for points; feedback shows name, points, pass/fail only)")
    parser.add_argument("--gradescope-autograder", type=Path, default=None, metavar="ZIP",
                        help="write a Gradescope autograder zip (setup.sh, run_autograder, tests) instead of grading")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run(args: argparse.Namespace) -> int:
    from coursekit.grading.grade import grade_submissions
    from coursekit.grading.sandbox import Limits

    limits = Limits(timeout_s=args.timeout, test_timeout_s=args.test_timeout, memory_mb=args.memory_mb,
                    disk_mb=args.disk_mb)
    if args.gradescope_autograder is not None:
        from coursekit.grading.gradescope import write_autograder

        path = write_autograder(args.gradescope_autograder, args.exercise, args.hidden_tests, limits)
        print(f"wrote {path}: upload it as the assignment's autograder (Gradescope, 'Configure Autograder')")
        return 0
    if args.submissions is None or args.out is None:
        raise ValueError("give SUBMISSIONS_DIR and --out DIR (or --gradescope-autograder ZIP)")
    summary = grade_submissions(args.submissions, args.out, args.exercise, jobs=args.jobs, limits=limits,
                                progress=not args.no_progress, hidden_tests=args.hidden_tests)
    for student in sorted(summary.students, key=lambda s: s.student):
        notes = [f"{g.exercise.id}: {g.status}" for g in student.grades if g.status != "ok"]
        print(f"{student.student:<24} {student.points:>6g} / {student.max_points:g}  {'; '.join(notes)}")
    for warning in summary.warnings:
        print(f"WARNING: {warning}")
    print(f"graded {len(summary.students)} submissions x {len(summary.exercises)} exercises in "
          f"{summary.seconds:.1f} s -> {summary.out / 'grades.csv'}")
    return 0
