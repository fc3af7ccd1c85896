"""load_exercise picks exercises/, solutions/ or a given folder, and re-reads edits."""

from __future__ import annotations

import shutil

import pytest

from coursekit.grading import load_exercise
from coursekit.grading.exercises import exercise_dir, repo_root


def test_default_env_and_explicit_folder(monkeypatch, tmp_path):
    root = repo_root()
    monkeypatch.delenv("COURSEKIT_EXERCISES", raising=False)
    assert load_exercise("chunk_windows").__file__ == str(root / "exercises" / "chunk_windows.py")
    with pytest.raises(NotImplementedError, match="Exercise 1.1"):
        load_exercise("chunk_windows").sequence_window_indices([5], 4, 1, 1)
    monkeypatch.setenv("COURSEKIT_EXERCISES", "solutions")
    solved = load_exercise("chunk_windows")
    assert solved.__file__ == str(root / "solutions" / "chunk_windows.py")
    indices, episode = solved.sequence_window_indices([5], 4, 1, 1)
    assert indices.shape == (2, 4) and episode.tolist() == [0, 0]
    shutil.copy(root / "solutions" / "chunk_windows.py", tmp_path / "chunk_windows.py")
    monkeypatch.setenv("COURSEKIT_EXERCISES", str(tmp_path))
    assert load_exercise("chunk_windows").__file__ == str(tmp_path / "chunk_windows.py")
    # an explicit folder beats the environment
    assert load_exercise("chunk_windows", root / "exercises").__file__ == str(root / "exercises" / "chunk_windows.py")


def test_edits_are_picked_up_without_restarting(tmp_path):
    path = tmp_path / "chunk_windows.py"
    path.write_text("def sequence_window_indices(*args):\n    return 1\n")
    assert load_exercise("chunk_windows", tmp_path).sequence_window_indices() == 1
    path.write_text("def sequence_window_indices(*args):\n    return 2\n")
    assert load_exercise("chunk_windows", tmp_path).sequence_window_indices() == 2


def test_clear_errors(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="unknown exercise 'nope'"):
        load_exercise("nope")
    with pytest.raises(FileNotFoundError, match="chunk_windows.py not found"):
        load_exercise("chunk_windows", tmp_path)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        exercise_dir(tmp_path / "missing")
    monkeypatch.setenv("COURSEKIT_ROOT", str(tmp_path))
    with pytest.raises(FileNotFoundError, match="COURSEKIT_ROOT"):
        repo_root()
    (tmp_path / "chunk_windows.py").write_text("def broken(:\n")
    with pytest.raises(SyntaxError):
        load_exercise("chunk_windows", tmp_path)
