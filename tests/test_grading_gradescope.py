"""The Gradescope autograder zip: run_autograder against a simulated /autograder tree writes the
results.json Gradescope expects (scores, hidden tests reduced to name/points/status)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from coursekit.cli import main
from coursekit.grading.exercises import get_exercise, repo_root

pytestmark = pytest.mark.slow  # one grading run: ~5-15 s

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
    env = {**os.environ, "AUTOGRADER_ROOT": str(tree), "COURSEKIT_PYTHON": sys.executable}
    env.pop("PYTHONPATH", None)
    proc = subprocess.run(["bash", str(tree / "source" / "run_autograder")], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    result = json.loads((tree / "results" / "results.json").read_text())
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


def test_check_never_sees_hidden_tests(tmp_path):
    import coursekit

    result = coursekit.check("chunk_windows", repo_root() / "solutions", show=False)
    assert {s.name for s in result.scores} == set(get_exercise("chunk_windows").tests)
