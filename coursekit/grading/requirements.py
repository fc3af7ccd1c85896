"""What the autograder image installs: ``requirements-grading.txt``, and the imports it must cover.

The Gradescope image (:mod:`coursekit.grading.gradescope`) holds only what grading imports: torch
(the CPU build), numpy, pytest, tqdm and psutil, each pinned to ``environment.txt``'s version,
plus what those need (``# via <package>`` lines). The file is installed with ``pip --no-deps``, so
nothing unlisted arrives. tests/test_grading_requirements.py holds it to an import scan of the
graded path; :func:`check_hidden_imports` holds an instructor's hidden tests to it.
"""

from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
from dataclasses import dataclass
from pathlib import Path

REQUIREMENTS_FILE = "requirements-grading.txt"
"""The file's name, at the repository's root and at the autograder zip's root."""

_PIN = re.compile(r"^(?P<name>[A-Za-z0-9][A-Za-z0-9._-]*)==(?P<version>[^\s#;]+)\s*(?:#\s*via\s+(?P<via>\S+))?\s*$")


@dataclass(frozen=True)
class Pin:
    """One line of the requirements file."""

    name: str
    """Distribution name, normalised (PEP 503: lower case, runs of ``-_.`` as ``-``)."""
    version: str
    """The exact version (``2.13.0+cpu`` for torch's CPU build)."""
    via: str = ""
    """The requirement that needs it (``# via torch``); empty for what the graded path imports itself."""


def normalise(name: str) -> str:
    """PEP 503's normal form of a distribution name (``Jinja2`` -> ``jinja2``, ``typing_extensions`` -> ``typing-extensions``)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def read_requirements(path: str | Path) -> list[Pin]:
    """Every pin of a requirements file; ValueError naming the line for anything but ``name==version [# via X]``."""
    pins: list[Pin] = []
    for number, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        match = _PIN.match(line.strip())
        if match is None:
            raise ValueError(f"{path}:{number}: {line.strip()!r} is not 'name==version' (optionally '# via <package>')")
        pins.append(Pin(normalise(match["name"]), match["version"], normalise(match["via"] or "")))
    names = [p.name for p in pins]
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: {sorted({n for n in names if names.count(n) > 1})} pinned more than once")
    return pins


def imported_modules(source: str, filename: str = "<source>") -> set[str]:
    """Top-level names of every absolute import in ``source``, at any depth (functions included)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def third_party(modules: set[str]) -> set[str]:
    """``modules`` less the standard library, ``__future__`` and coursekit itself."""
    return {m for m in modules if m not in sys.stdlib_module_names and m not in ("__future__", "coursekit")}


def providers(module: str) -> set[str]:
    """Normalised names of the installed distributions that provide top-level ``module`` (empty: none here)."""
    return {normalise(d) for d in importlib.metadata.packages_distributions().get(module, [])}


def check_hidden_imports(folder: str | Path, pins: list[Pin]) -> None:
    """ValueError naming the file and module when a hidden test in ``folder`` (its ``*.py`` but
    conftest.py, as :func:`coursekit.grading.report.load_hidden_tests` takes them) imports a package
    the image lacks."""
    installed, direct = {p.name for p in pins}, sorted(p.name for p in pins if not p.via)
    for path in sorted(Path(folder).glob("*.py")):
        if path.name == "conftest.py":
            continue
        for module in sorted(third_party(imported_modules(path.read_text(encoding="utf-8"), str(path)))):
            if not providers(module) & installed:
                raise ValueError(f"hidden test {path} imports {module!r}, which the autograder image does not install "
                                 f"(it holds {', '.join(direct)} and what they need): add its pin to {REQUIREMENTS_FILE} "
                                 "or drop the import")
