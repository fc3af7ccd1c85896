"""The ``coursekit`` command: one sub-command per module in ``coursekit/commands/``.

Each command module exposes ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``, and imports heavy libraries (torch, mujoco, meshcat) only inside ``run``,
so ``coursekit --help`` is instant.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# sub-command -> module under coursekit.commands
COMMANDS: dict[str, str] = {
    "demo": "demo",
    "collect": "collect",
    "train": "train",
    "eval": "evaluate",
    "exercises": "exercises",
    "check": "check",
    "grade": "grade",
}


def _load(name: str):
    return importlib.import_module(f"coursekit.commands.{COMMANDS[name]}")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="coursekit", description="Action-chunk policies (Diffusion Policy, ACT) on a laptop CPU.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        if only is not None and name != only:
            continue
        try:
            module = _load(name)
        except ModuleNotFoundError as exc:  # a command whose module is not written yet
            if not exc.name or not exc.name.startswith("coursekit.commands"):
                raise
            continue
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    only = argv[0] if argv and argv[0] in COMMANDS else None
    parser = build_parser(only)
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 0 if not argv else 2
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileNotFoundError) as exc:  # bad input: a clear message, not a traceback
        print(f"coursekit {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
