"""The ``coursekit`` command: one sub-command per module in ``coursekit/commands/``.

Each command module exposes ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``, and imports heavy libraries (torch, mujoco, meshcat) only inside ``run``,
so ``coursekit --help`` is instant.

One error path: a bad flag (argparse) and any failure inside a command print ONE line,
``coursekit CMD: error: <what, and which value>``, and exit with status 2 (130 on Ctrl-C).
``--debug`` (anywhere on the command line) shows the full traceback instead.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import NoReturn

# sub-command -> module under coursekit.commands
COMMANDS: dict[str, str] = {
    "demo": "demo",
    "collect": "collect",
    "train": "train",
    "eval": "evaluate",
    "exercises": "exercises",
    "check": "check",
    "grade": "grade",
    "export": "export",
    "import": "import_",
}


def _load(name: str):
    return importlib.import_module(f"coursekit.commands.{COMMANDS[name]}")


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error: ``coursekit CMD: error: ...`` (no usage block), exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {_one_line(message)} (see `{self.prog} --help`)\n")


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = _Parser(prog="coursekit", description="Action-chunk policies (Diffusion Policy, ACT) on a laptop CPU.")
    parser.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
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
        p.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
        p.set_defaults(_run=module.run, _parser=p)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv  # accepted before or after the command name
    argv = [a for a in argv if a != "--debug"]
    only = argv[0] if argv and argv[0] in COMMANDS else None
    parser = build_parser(only)
    try:
        args, unknown = parser.parse_known_args(argv)
        if unknown:  # reported by the command's own parser: "coursekit train: error: ..."
            getattr(args, "_parser", parser).error(f"unrecognized arguments: {' '.join(unknown)}")
    except SystemExit as exc:  # argparse already printed its one-line error (status 2) or --help (0)
        return int(exc.code or 0)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 0 if not argv else 2
    if debug:
        return int(args._run(args) or 0)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print(f"coursekit {args.command}: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError) as exc:  # bad input, a missing or unwritable file: the message says it all
        print(f"coursekit {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:  # anything else is a bug or an environment problem: still one line
        print(f"coursekit {args.command}: error: {type(exc).__name__}: {_one_line(exc)} "
              f"(run again with --debug for the traceback)", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
