"""The Gradescope autograder: the same graded tests, one container per submission (any class size).

``coursekit grade --gradescope-autograder autograder.zip [--exercise ID ...] [--hidden-tests DIR]``
writes a zip with, at its root:

- ``setup.sh``: run once when Gradescope builds the image (:data:`IMAGE`, as root): installs
  bubblewrap and Python 3.11, and ONLY ``requirements-grading.txt`` (torch's CPU build, numpy,
  pytest, tqdm, psutil and what they need; :data:`REQUIREMENTS_FILE`) into
  ``source/.venv``, with ``--no-deps`` so nothing unlisted arrives;
- ``run_autograder``: run per submission; grades ``/autograder/submission`` with
  ``python -m coursekit.grading.gradescope run`` and writes ``/autograder/results/results.json``;
- the ``coursekit`` package (no checkpoints; on ``PYTHONPATH``, not installed), ``pyproject.toml``,
  ``requirements-grading.txt``, the graded test files of the chosen exercises, the hidden tests
  (``hidden/``) and ``autograder.json`` (exercises, limits, image). No ``solutions/``.

``AUTOGRADER_ROOT`` (default ``/autograder``) and ``COURSEKIT_PYTHON`` (default the venv's
python) override the paths, so a test can run ``run_autograder`` against a simulated tree.
"""

from __future__ import annotations

import argparse
import ast
import importlib.metadata
import json
import os
import re
import stat
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

from coursekit.atomic import atomic_path, atomic_write_text
from coursekit.grading.exercises import EXERCISES, get_exercise, repo_root
from coursekit.grading.report import load_hidden_tests
from coursekit.grading.sandbox import Limits

REQUIREMENTS_FILE = "requirements-grading.txt"
"""What the image installs, at the repository's root and at the zip's root: torch (the CPU build),
numpy, pytest, tqdm and psutil, each pinned to ``environment.txt``'s version, plus what those need
(``# via <package>`` lines), installed with ``pip --no-deps`` so nothing unlisted arrives.
tests/test_grading_requirements.py holds it to an import scan of the graded path;
:func:`check_hidden_imports` holds an instructor's hidden tests to it."""

IMAGE = {"os": "Ubuntu 22.04", "python": "3.11"}
"""The image the zip is written for: Gradescope's default base image (Ubuntu 22.04, whose own
python3 is 3.10) with Ubuntu's python3.11 package; where the image's python3 is already >= 3.11
(the Ubuntu 24.04 image: 3.12) setup.sh uses that instead."""
TORCH_CPU_INDEX = "https://download.pytorch.org/whl/cpu"
"""Where setup.sh finds ``torch==<version>+cpu`` (PyPI has only the CUDA build for Linux)."""

SETUP = f"""#!/usr/bin/env bash
# Gradescope image build, as root. Written for {IMAGE["os"]} (Gradescope's default base image)
# and Python {IMAGE["python"]}: bubblewrap, Python and ONLY {REQUIREMENTS_FILE} (torch's CPU build,
# numpy, pytest and what grading imports; no notebooks, browsers or simulators).
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq bubblewrap python3 python3-venv python3-pip >/dev/null
PY=""
for candidate in python{IMAGE["python"]} python3; do
  if command -v "$candidate" >/dev/null && "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
    PY="$candidate"; break
  fi
done
if [ -z "$PY" ]; then
  apt-get install -y -qq python{IMAGE["python"]} python{IMAGE["python"]}-venv >/dev/null
  PY=python{IMAGE["python"]}
fi
cd /autograder/source
"$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
# --no-deps: the file pins every package the grader needs; the CPU index serves torch's +cpu build
.venv/bin/python -m pip install -q --no-deps --extra-index-url {TORCH_CPU_INDEX} -r {REQUIREMENTS_FILE}
.venv/bin/python -m pip check
"""

RUN = """#!/usr/bin/env bash
# Gradescope, per submission: grade /autograder/submission, write /autograder/results/results.json.
set -u
ROOT="${AUTOGRADER_ROOT:-/autograder}"
SRC="$ROOT/source"
PY="${COURSEKIT_PYTHON:-$SRC/.venv/bin/python}"
mkdir -p "$ROOT/results"
cd "$SRC"
PYTHONPATH="$SRC" COURSEKIT_ROOT="$SRC" OMP_NUM_THREADS=1 exec "$PY" -m coursekit.grading.gradescope run \\
  --source "$SRC" --submission "$ROOT/submission" --results "$ROOT/results/results.json"
"""


# ----------------------------------------------------------------- the image's requirements
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


# ----------------------------------------------------------------- the zip
def _package_files(package: Path):
    for path in sorted(package.rglob("*")):
        rel = path.relative_to(package)
        if path.is_file() and "__pycache__" not in rel.parts and rel.parts[0] != "checkpoints" \
                and path.suffix not in (".pyc", ".safetensors", ".npz"):
            yield path, rel


def write_autograder(zip_path: str | Path, exercises: list[str] | None = None, hidden_tests: str | Path | None = None,
                     limits: Limits | None = None, lock=None) -> Path:
    """Write the autograder zip (refuses to overwrite an existing file or link); returns its path.

    The zip is built in a temporary with a random name recorded in ``zip_path``'s lock (``lock``,
    the caller's :class:`coursekit.output_lock.OutputLock`, or one taken here), then renamed into place.
    """
    zip_path = Path(zip_path)
    if os.path.lexists(zip_path):
        raise ValueError(f"{zip_path} already exists: choose a new name (nothing was written)")
    if not zip_path.parent.is_dir():
        raise FileNotFoundError(f"folder {str(zip_path.parent)!r} does not exist")
    chosen = [get_exercise(e) for e in exercises] if exercises else list(EXERCISES)
    hidden = load_hidden_tests(hidden_tests).sources if hidden_tests is not None else {}
    root = repo_root()
    if hidden_tests is not None:  # load_hidden_tests checked the files are UTF-8 Python
        check_hidden_imports(hidden_tests, read_requirements(root / REQUIREMENTS_FILE))
    limits = limits or Limits()
    config = {"exercises": [e.id for e in chosen],
              "limits": {k: getattr(limits, k) for k in ("timeout_s", "test_timeout_s", "memory_mb", "output_mb", "disk_mb")},
              "image": IMAGE}
    with atomic_path(zip_path, suffix=".zip", lock=lock) as tmp, \
            zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        def add_text(name: str, text: str, executable: bool = False) -> None:
            info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
            info.external_attr = ((0o755 if executable else 0o644) | stat.S_IFREG) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, text)

        add_text("setup.sh", SETUP, executable=True)
        add_text("run_autograder", RUN, executable=True)
        add_text("autograder.json", json.dumps(config, indent=1) + "\n")
        for name in ("pyproject.toml", REQUIREMENTS_FILE):
            add_text(name, (root / name).read_text())
        for path, rel in _package_files(root / "coursekit"):
            zf.write(path, f"coursekit/{rel.as_posix()}")
        add_text("tests/exercises/conftest.py", (root / "tests" / "exercises" / "conftest.py").read_text())
        for e in chosen:
            add_text(e.test_module, (root / e.test_module).read_text())
        for name, data in hidden.items():
            add_text(f"hidden/{name}", data.decode())
    return zip_path


def run(source: Path, submission: Path, results: Path) -> int:
    """Grade one Gradescope submission folder and write its results.json."""
    from coursekit.grading.grade import grade_submissions

    config = json.loads((source / "autograder.json").read_text())
    limits = Limits(**config["limits"])
    hidden = source / "hidden" if (source / "hidden").is_dir() else None
    with tempfile.TemporaryDirectory(prefix="coursekit-gradescope-") as tmp:
        subs = Path(tmp) / "submissions"
        subs.mkdir()
        (subs / "submission").symlink_to(submission.resolve(), target_is_directory=True)
        summary = grade_submissions(subs, Path(tmp) / "out", config["exercises"], jobs=1, limits=limits,
                                    progress=False, hidden_tests=hidden)
        result = json.loads((Path(tmp) / "out" / "submission" / "results.json").read_text())
    if summary.mode != "bwrap":
        result["output"] += "\n(graded without OS isolation: bubblewrap was not usable in this container)"
    atomic_write_text(results, json.dumps(result, indent=2) + "\n")
    print(result["output"])
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m coursekit.grading.gradescope")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="grade one submission (what run_autograder calls)")
    p.add_argument("--source", type=Path, required=True)
    p.add_argument("--submission", type=Path, required=True)
    p.add_argument("--results", type=Path, required=True)
    args = parser.parse_args(argv)
    return run(args.source, args.submission, args.results)


if __name__ == "__main__":
    sys.exit(main())
