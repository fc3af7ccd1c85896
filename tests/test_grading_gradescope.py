"""The Gradescope autograder zip: run_autograder against a simulated /autograder tree writes the
results.json Gradescope expects (scores, hidden tests reduced to name/points/status), run by a
Python that sees only requirements-grading.txt's packages (what the zip's setup.sh installs)."""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
import venv
import zipfile
from pathlib import Path

import pytest

from coursekit.cli import main
from coursekit.grading.exercises import get_exercise, repo_root
from coursekit.grading.gradescope import REQUIREMENTS_FILE, read_requirements

pytestmark = pytest.mark.slow  # two grading runs: ~10-30 s

HIDDEN = '''
import numpy as np

EXERCISE = "chunk_windows"
POINTS = {"test_long_episode": 2, "test_secret_failing": 1}


def test_long_episode(student):
    indices, episode = student.sequence_window_indices(np.array([500]), 16, 2, 8)
    assert indices.shape == (500 - 16 + 2 + 8 - 1, 16)


def test_secret_failing(student):
    assert False, "SECRET-MESSAGE the student must not see"
'''


def grading_only_python(home: Path) -> Path:
    """The python of a new venv holding only requirements-grading.txt's distributions, their files
    hard-linked (copied across file systems) from this environment: seconds, not a download. The
    pip install itself (the pinned versions, from the registry) is benchmarks/check_grading_image.py."""
    venv.create(home, with_pip=False, symlinks=True)
    site = next(home.glob("lib/python*/site-packages"))
    for pin in read_requirements(repo_root() / REQUIREMENTS_FILE):
        dist = importlib.metadata.distribution(pin.name)
        if not pin.via:  # environment.txt pins these to the same versions
            assert dist.version == pin.version.split("+")[0] or dist.version == pin.version, (pin, dist.version)
        for file in dist.files or []:
            source = Path(dist.locate_file(file))
            if file.parts[0] == ".." or not source.is_file():
                continue  # scripts in bin/; files RECORD lists but that are gone
            (site / file).parent.mkdir(parents=True, exist_ok=True)
            try:
                os.link(source, site / file)
            except OSError:
                (site / file).write_bytes(source.read_bytes())
    return home / "bin" / "python"


def run_autograder(tree: Path, python: Path) -> dict:
    """Run the zip's run_autograder on ``tree`` (a simulated /autograder) and return its results.json."""
    env = {**os.environ, "AUTOGRADER_ROOT": str(tree), "COURSEKIT_PYTHON": str(python)}
    env.pop("PYTHONPATH", None)
    proc = subprocess.run(["bash", str(tree / "source" / "run_autograder")], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads((tree / "results" / "results.json").read_text())


def test_autograder_zip_runs_against_a_simulated_tree(tmp_path, capsys):
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "test_more_windows.py").write_text(HIDDEN)
    archive = tmp_path / "autograder.zip"
    assert main(["grade", "--gradescope-autograder", str(archive), "--exercise", "chunk_windows",
                 "--hidden-tests", str(hidden), "--timeout", "60", "--test-timeout", "20"]) == 0
    assert main(["grade", "--gradescope-autograder", str(archive), "--exercise", "chunk_windows"]) == 2
    assert "already exists" in capsys.readouterr().err
    names = zipfile.ZipFile(archive).namelist()
    assert {"setup.sh", "run_autograder", "autograder.json", "tests/exercises/test_chunk_windows.py",
            "hidden/hidden_test_more_windows.py", "coursekit/grading/worker.py"} <= set(names)
    assert not [n for n in names if n.startswith("solutions/") or "checkpoints/" in n or "__pycache__" in n]

    tree = tmp_path / "autograder"
    zipfile.ZipFile(archive).extractall(tree / "source")
    (tree / "submission" / "nested").mkdir(parents=True)  # modules one folder down, as students upload them
    (tree / "submission" / "nested" / "chunk_windows.py").write_text(
        (repo_root() / "solutions" / "chunk_windows.py").read_text())
    python = grading_only_python(tmp_path / "venv")
    missing = subprocess.run([str(python), "-c", "import scipy"], capture_output=True, text=True)
    assert "No module named 'scipy'" in missing.stderr, "the grading venv sees more than its requirements"
    result = run_autograder(tree, python)
    visible = get_exercise("chunk_windows").max_points
    assert result["score"] == visible + 2  # all visible tests and the passing hidden one
    tests = {t["name"]: t for t in result["tests"]}
    assert len(tests) == len(get_exercise("chunk_windows").tests) + 2
    secret = tests["1.1 chunk_windows: test_secret_failing (hidden)"]
    assert secret["status"] == "failed" and secret["score"] == 0 and secret["max_score"] == 1
    assert "SECRET" not in json.dumps(result), "a hidden test's message reached the student"
    assert tests["1.1 chunk_windows: test_long_episode (hidden)"]["status"] == "passed"
    assert all(t["status"] == "passed" for n, t in tests.items() if "hidden" not in n)
    assert str(tmp_path) not in json.dumps(result), "an absolute path of the grading machine leaked"

    # the untouched stub: zero, every test failing on the exercise's NotImplementedError (not an import)
    (tree / "submission" / "nested" / "chunk_windows.py").write_text(
        (repo_root() / "exercises" / "chunk_windows.py").read_text())
    result = run_autograder(tree, python)
    visible = [t for t in result["tests"] if "hidden" not in t["name"]]
    assert result["score"] == 0 and visible and all(t["status"] == "failed" for t in visible)
    assert all("NotImplementedError: Exercise 1.1" in t["output"] for t in visible), visible[0]["output"]


def test_check_never_sees_hidden_tests(tmp_path):
    import coursekit

    result = coursekit.check("chunk_windows", repo_root() / "solutions", show=False)
    assert {s.name for s in result.scores} == set(get_exercise("chunk_windows").tests)
