"""``coursekit check ID``: run one exercise's graded tests on your module and print the table."""

from __future__ import annotations

import argparse
from pathlib import Path

from coursekit.commands._args import float_in

HELP = "run one exercise's graded tests on your exercises/ module and print test, points, pass/FAIL, hint"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("exercise", help="exercise id, e.g. chunk_windows (`coursekit exercises list` shows them)")
    parser.add_argument("--dir", type=Path, default=None,
                        help="folder with the module (default: exercises/, or solutions/ with COURSEKIT_EXERCISES=solutions)")
    parser.add_argument("--timeout", type=float_in(0.0, 3600.0, lo_open=True), default=120.0,
                        help="wall-clock limit for the test run, in seconds (at most 3600)")


def run(args: argparse.Namespace) -> int:
    from coursekit.grading.notebook import check

    result = check(args.exercise, args.dir, timeout=args.timeout)
    return 0 if result.all_passed else 1
