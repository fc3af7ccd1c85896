"""``coursekit exercises build|list``: generate exercises/ and solutions/ from the marked library code."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "generate exercises/ (stubs) and solutions/ from the marked library code, or list the exercises"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=["build", "list"], help="build: (re)write both folders; list: show the registry")
    parser.add_argument("--check", action="store_true", help="build: write nothing, exit 1 if a folder differs from a fresh build")
    parser.add_argument("--root", type=Path, default=None, help="repository root (default: the checkout holding coursekit)")


def run(args: argparse.Namespace) -> int:
    from coursekit.grading.build import build_exercises
    from coursekit.grading.exercises import EXERCISES, exercise_number

    if args.action == "list":
        for e in EXERCISES:
            print(f"{exercise_number(e):>5}  {e.id:<22} {e.max_points:>4g} pts  {e.title}  [{e.source}: {', '.join(e.objects)}]")
        return 0
    changed = build_exercises(args.root, check=args.check)
    verb = "differs from a fresh build" if args.check else "written"
    for path in changed:
        print(f"{verb}: {path}")
    if args.check:
        print("exercises/ and solutions/ are up to date" if not changed else
              "run `coursekit exercises build` (or `make exercises`) and commit the result")
        return 1 if changed else 0
    print(f"{len(EXERCISES)} exercises: {len(changed)} file(s) updated, the rest unchanged")
    return 0
