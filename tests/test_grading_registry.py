"""The registry agrees with the graded test files and the library's marked code."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from coursekit.grading.exercises import EXERCISES, Exercise, exercise_number, get_exercise, repo_root

EXPECTED_IDS = {"chunk_windows"}  # ids the design contract promises (others join as they land)


def _test_functions(path: Path) -> tuple[list[str], str | None]:
    tree = ast.parse(path.read_text())
    names = [n.name for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")]
    constant = None
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "EXERCISE" for t in node.targets):
            constant = ast.literal_eval(node.value)
    return names, constant


@pytest.mark.parametrize("exercise", EXERCISES, ids=lambda e: e.id)
def test_registry_matches_test_file_and_source(exercise):
    path = repo_root() / exercise.test_module
    assert path.is_file(), f"{exercise.id}: missing {exercise.test_module}"
    names, constant = _test_functions(path)
    assert constant == exercise.id, f"{path.name} must set EXERCISE = {exercise.id!r}, got {constant!r}"
    assert sorted(names) == sorted(exercise.tests), (
        f"{exercise.id}: registry tests {sorted(exercise.tests)} != test functions {sorted(names)}")
    module = importlib.import_module(exercise.source)
    for obj in exercise.objects:
        assert hasattr(module, obj), f"{exercise.source} has no {obj}"
    assert exercise.max_points == sum(spec[0] for spec in exercise.tests.values()) > 0


def test_ids_unique_numbering_and_lookup():
    ids = [e.id for e in EXERCISES]
    assert len(ids) == len(set(ids)) and EXPECTED_IDS <= set(ids)
    assert [e.chapter for e in EXERCISES] == sorted(e.chapter for e in EXERCISES), "keep the registry sorted by chapter"
    assert exercise_number(get_exercise("chunk_windows")) == "1.1"
    with pytest.raises(ValueError, match="unknown exercise 'nope'.*chunk_windows"):
        get_exercise("nope")


@pytest.mark.parametrize("kwargs, error", [
    (dict(id="Bad-Id"), "snake_case"),
    (dict(chapter=-1), "chapter"),
    (dict(objects=()), "objects"),
    (dict(tests={}), "at least one"),
    (dict(tests={"check_x": (1, "h")}), "test_"),
    (dict(tests={"test_x": (0, "h")}), "points > 0"),
    (dict(tests={"test_x": (1, "")}), "points > 0, hint"),
])
def test_exercise_validation_shows_the_bad_value(kwargs, error):
    base = dict(id="ok", chapter=1, title="t", source="m", objects=("f",), tests={"test_x": (1, "h")})
    with pytest.raises(ValueError, match=error):
        Exercise(**{**base, **kwargs})


def test_graded_test_basenames_do_not_collide_with_other_tests():
    """tests/ has no __init__.py: two test files with one basename break pytest's collection."""
    tests = repo_root() / "tests"
    graded = {p.name for p in (tests / "exercises").glob("test_*.py")}
    others = {p.name for p in tests.rglob("test_*.py") if p.parent != tests / "exercises"}
    assert not graded & others, f"rename one of {sorted(graded & others)}"
