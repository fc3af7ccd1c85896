"""``coursekit grade SUBMISSIONS_DIR --out DIR``: grade every submission in a sandboxed subprocess.

The output policy of every command (:mod:`coursekit.outputs`) applies: --out is checked before
anything is graded (never the submissions folder, a student's folder or the hidden tests, never
inside or around them, never a user's folder or a link), locked, and graded into a staging folder
that replaces it in one step when complete. An earlier grade output is replaced only with
--overwrite, and only if it is unchanged since coursekit wrote it
(:mod:`coursekit.commands._grade_output`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from coursekit.commands._args import float_in, int_in, output_path

HELP = "grade a folder of submissions (copies or zips of exercises/): class CSV, Gradescope JSON, feedback"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("submissions", type=Path, nargs="?", help="folder with one sub-folder or .zip per student")
    parser.add_argument("--out", type=output_path,
                        help="new folder for grades.csv and <student>/results.json, feedback.md (written when complete)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an earlier `coursekit grade` output at --out (only if unchanged since it was written)")
    parser.add_argument("--exercise", action="append", default=None, metavar="ID",
                        help="grade only this exercise (repeatable; default: all registered)")
    # bounded: a limit of 1e300 s is no limit (a hanging submission would hang the class), 1e9 jobs no plan
    parser.add_argument("--jobs", type=int_in(1, 256), default=1, help="submissions graded in parallel (one subprocess each)")
    parser.add_argument("--timeout", type=float_in(0.0, 3600.0, lo_open=True), default=120.0,
                        help="wall-clock limit per student x exercise, seconds (at most 3600)")
    parser.add_argument("--test-timeout", type=float_in(0.0, 3600.0, lo_open=True), default=10.0,
                        help="limit per test, seconds (at most 3600)")
    parser.add_argument("--memory-mb", type=int_in(256, 1 << 20), default=2048, help="address-space cap per subprocess, MiB")
    parser.add_argument("--disk-mb", type=int_in(1, 1 << 16), default=64,
                        help="size of each worker's private tmpfs (with bubblewrap), MiB")
    parser.add_argument("--hidden-tests", type=Path, default=None, metavar="DIR",
                        help="instructor-only tests (count for points; feedback shows name, points, pass/fail only)")
    parser.add_argument("--gradescope-autograder", type=output_path, default=None, metavar="ZIP",
                        help="write a Gradescope autograder zip (setup.sh, run_autograder, tests) instead of grading")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run(args: argparse.Namespace) -> int:
    from coursekit.grading.sandbox import Limits

    limits = Limits(timeout_s=args.timeout, test_timeout_s=args.test_timeout, memory_mb=args.memory_mb,
                    disk_mb=args.disk_mb)
    if args.gradescope_autograder is not None:
        return _write_autograder(args, limits)
    if args.submissions is None or args.out is None:
        raise ValueError("give SUBMISSIONS_DIR and --out DIR (or --gradescope-autograder ZIP)")
    from coursekit.commands._grade_output import grade_inputs, grade_output_foreign
    from coursekit.outputs import claim_output

    inputs = grade_inputs(args.submissions, args.hidden_tests)
    with claim_output(args.out, what="coursekit grade output", foreign=grade_output_foreign, directory=True,
                      overwrite=args.overwrite, inputs=inputs) as lock:
        for leftover in lock.swept:
            print(f"removed {str(leftover)!r}, left by an interrupted earlier run")
        summary = _grade_into(args, limits, lock)
    for student in sorted(summary.students, key=lambda s: s.student):
        notes = [f"{g.exercise.id}: {g.status}" for g in student.grades if g.status != "ok"]
        print(f"{student.student:<24} {student.points:>6g} / {student.max_points:g}  {'; '.join(notes)}")
    for warning in summary.warnings:
        print(f"WARNING: {warning}")
    print(f"graded {len(summary.students)} submissions x {len(summary.exercises)} exercises in "
          f"{summary.seconds:.1f} s -> {args.out / 'grades.csv'}")
    return 0


def _grade_into(args: argparse.Namespace, limits, lock):
    """Grade into a recorded staging folder beside --out, record its files, swap it in."""
    from coursekit.commands._grade_output import write_record
    from coursekit.grading.grade import grade_submissions
    from coursekit.outputs import replace_dir, staging_dir

    with staging_dir(args.out, lock) as tmp:
        summary = grade_submissions(args.submissions, tmp, args.exercise, jobs=args.jobs, limits=limits,
                                    progress=not args.no_progress, hidden_tests=args.hidden_tests)
        write_record(tmp)
        replace_dir(tmp, args.out, lock)  # an earlier output is now in tmp, removed with it
    return summary


def _write_autograder(args: argparse.Namespace, limits) -> int:
    """--gradescope-autograder ZIP: a new file (never replaced), outside the package it packs and the hidden tests."""
    import coursekit
    from coursekit.grading.gradescope import write_autograder
    from coursekit.outputs import claim_output

    package = Path(coursekit.__file__).resolve().parent
    with claim_output(args.gradescope_autograder, what="zip", foreign=None, directory=False,
                      inputs=[package, args.hidden_tests], flag="--gradescope-autograder") as lock:
        path = write_autograder(args.gradescope_autograder, args.exercise, args.hidden_tests, limits, lock=lock)
    print(f"wrote {path}: upload it as the assignment's autograder (Gradescope, 'Configure Autograder')")
    return 0
