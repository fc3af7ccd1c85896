"""The autograder image installs what grading imports and nothing else.

An import scan follows the graded path (what ``run_autograder`` runs: coursekit.grading.gradescope,
the worker, the graded tests and their conftest, the student modules, every coursekit module they
import, at any depth) and names its third-party imports; ``requirements-grading.txt`` must pin
exactly those (GRADED), each at environment.txt's version, plus their dependency closure. Adding
an import to a graded path without its requirement fails here. That the image really grades is
checked by tests/test_grading_gradescope.py (a venv holding only these packages) and, with a
real ``pip install``, by ``benchmarks/check_grading_image.py``.
"""

from __future__ import annotations

import ast
import importlib.metadata
import json
import re
import zipfile
from pathlib import Path

import pytest
from packaging.markers import default_environment
from packaging.requirements import Requirement

from coursekit.cli import main
from coursekit.grading.exercises import EXERCISES, repo_root
from coursekit.grading.gradescope import IMAGE, SETUP, TORCH_CPU_INDEX, write_autograder
from coursekit.grading.gradescope import (REQUIREMENTS_FILE, imported_modules, normalise, providers,
                                            read_requirements, third_party)

ROOT = repo_root()
GRADED = {"numpy": "numpy", "psutil": "psutil", "pytest": "pytest", "torch": "torch", "tqdm": "tqdm"}
"""Import name -> distribution: the third-party packages the graded path imports."""
NOT_WHILE_GRADING = {
    "gymnasium": "coursekit.tasks.registry imports it to register the gym ids, which `import coursekit` "
                 "does under `except ImportError` (coursekit/__init__.py); grading never makes an env",
}
"""Imported on the graded path's files but never needed to grade (the reason is the value)."""
SKIPPED_FUNCTIONS = {"golden_values"}
"""Functions of the graded tests never run while grading: golden_values() imports diffusers and runs
only from tests/exercises/golden.py, which stores its values in the test module."""
FACTORY = re.compile(r"^(coursekit(?:\.\w+)+):\w+$")
"""``sandbox.new("coursekit.x.y:Name", ...)``: a module the worker imports by name."""


def _module_file(name: str) -> Path | None:
    path = ROOT / Path(*name.split("."))
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def _imports(path: Path) -> tuple[set[str], set[str]]:
    """(coursekit modules named, third-party top-level imports) of one file, skipping SKIPPED_FUNCTIONS."""
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name in SKIPPED_FUNCTIONS:
            node.body = [ast.Pass()]
    ours, theirs = set(), third_party(imported_modules(ast.unparse(tree)))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            ours.update(a.name for a in node.names if a.name.split(".")[0] == "coursekit")
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "coursekit":
            ours.add(node.module)
            ours.update(f"{node.module}.{a.name}" for a in node.names)  # `from pkg import module`
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "new" \
                and node.args and isinstance(node.args[0], ast.Constant) and FACTORY.match(str(node.args[0].value)):
            ours.add(FACTORY.match(node.args[0].value)[1])
    return ours, theirs


def graded_path_imports() -> dict[str, set[str]]:
    """Third-party top-level module -> the files of the graded path that import it."""
    todo = [ROOT / "tests" / "exercises" / "conftest.py", *(ROOT / e.test_module for e in EXERCISES),
            *(ROOT / "solutions" / f"{e.id}.py" for e in EXERCISES)]
    modules = ["coursekit.grading.gradescope", "coursekit.grading.worker"]
    seen: set[Path] = set()
    found: dict[str, set[str]] = {}
    while todo or modules:
        if modules:  # a module and every package above it (their __init__ runs on import)
            parts = modules.pop().split(".")
            todo.extend(f for i in range(1, len(parts) + 1) if (f := _module_file(".".join(parts[:i]))))
            continue
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        ours, theirs = _imports(path)
        modules.extend(ours)
        for name in theirs:
            found.setdefault(name, set()).add(str(path.relative_to(ROOT)))
    return found


def test_requirements_pin_exactly_what_the_graded_path_imports():
    found = graded_path_imports()
    assert set(found) == set(GRADED) | set(NOT_WHILE_GRADING), (
        f"the graded path imports {sorted(set(found) - set(GRADED) - set(NOT_WHILE_GRADING))} beyond "
        f"{sorted(GRADED)} (add each to {REQUIREMENTS_FILE} and GRADED) and no longer "
        f"{sorted(set(GRADED) - set(found))}: {json.dumps({k: sorted(v) for k, v in found.items()}, indent=1)}")
    assert "coursekit/grading/worker.py" in found["torch"] and "tests/exercises/conftest.py" in found["pytest"]
    for module, dist in GRADED.items():
        assert dist in providers(module), f"{module} is not provided by {dist} here"
    direct = {p.name for p in read_requirements(ROOT / REQUIREMENTS_FILE) if not p.via}
    assert direct == set(GRADED.values())


def test_direct_pins_are_environment_txt_and_torch_is_the_cpu_build():
    env = dict(line.split("==") for line in (ROOT / "environment.txt").read_text().splitlines()
               if "==" in line and not line.startswith("#"))
    pins = {p.name: p for p in read_requirements(ROOT / REQUIREMENTS_FILE)}
    assert pins["torch"].version.endswith("+cpu"), "torch must be the CPU build (PyPI's Linux torch is CUDA)"
    for name in GRADED.values():
        assert pins[name].version.split("+")[0] == env[name], f"{name}: {pins[name].version} vs environment.txt"


def _requires(name: str, env: dict[str, str]) -> set[str]:
    """Normalised names ``name``'s installed metadata requires (markers evaluated, no extras)."""
    out = set()
    for text in importlib.metadata.requires(name) or []:
        req = Requirement(text)
        if req.marker is None or req.marker.evaluate({**env, "extra": ""}):
            out.add(normalise(req.name))
    return out


def test_requirements_are_the_dependency_closure_and_nothing_more():
    """--no-deps installs the file as is: every dependency (on Linux, this Python) must be in it, nothing else."""
    pins = read_requirements(ROOT / REQUIREMENTS_FILE)
    env = {**default_environment(), "sys_platform": "linux", "platform_system": "Linux"}
    closure, todo = set(), [p.name for p in pins if not p.via]
    while todo:
        name = todo.pop()
        if name not in closure:
            closure.add(name)
            todo.extend(_requires(name, env))
    assert {p.name for p in pins} == closure
    for pin in pins:
        assert not pin.via or pin.name in _requires(pin.via, env), f"{pin.name} is not a dependency of {pin.via}"


def test_zip_installs_only_the_grading_requirements_and_states_its_image(tmp_path):
    archive = write_autograder(tmp_path / "autograder.zip", ["chunk_windows"])
    zf = zipfile.ZipFile(archive)
    names = set(zf.namelist())
    assert "environment.txt" not in names
    assert zf.read(REQUIREMENTS_FILE) == (ROOT / REQUIREMENTS_FILE).read_bytes()
    setup = zf.read("setup.sh").decode()
    assert setup == SETUP
    installs = [line for line in setup.splitlines() if " pip install " in line]
    assert installs == [".venv/bin/python -m pip install -q --upgrade pip",
                        f".venv/bin/python -m pip install -q --no-deps --extra-index-url {TORCH_CPU_INDEX} "
                        f"-r {REQUIREMENTS_FILE}"]
    assert f"# Gradescope image build, as root. Written for {IMAGE['os']}" in setup
    assert f"apt-get install -y -qq python{IMAGE['python']} python{IMAGE['python']}-venv" in setup
    assert json.loads(zf.read("autograder.json"))["image"] == IMAGE


@pytest.mark.parametrize("line, module", [("import scipy.linalg", "scipy"), ("from diffusers import DDIMScheduler", "diffusers"),
                                          ("def helper():\n    import mujoco", "mujoco")])
def test_hidden_test_importing_what_the_image_lacks_is_refused(tmp_path, capsys, line, module):
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "test_more.py").write_text(f'{line}\nimport numpy as np\n\nEXERCISE = "chunk_windows"\n'
                                         'POINTS = {"test_a": 1}\n\n\ndef test_a(student):\n    assert True\n')
    archive = tmp_path / "autograder.zip"
    assert main(["grade", "--gradescope-autograder", str(archive), "--hidden-tests", str(hidden)]) == 2
    err = capsys.readouterr().err.strip()
    assert re.fullmatch(rf"coursekit grade: error: hidden test {re.escape(str(hidden / 'test_more.py'))} imports '{module}', which the autograder image does "
                        rf"not install \(it holds numpy, psutil, pytest, torch, tqdm and what they need\): add its pin "
                        rf"to {REQUIREMENTS_FILE} or drop the import", err), err
    assert not archive.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["hidden"]
    (hidden / "test_more.py").write_text((hidden / "test_more.py").read_text().replace(line, "import torch, math"))
    assert write_autograder(archive, ["chunk_windows"], hidden_tests=hidden).is_file()
