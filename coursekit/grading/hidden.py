"""Hidden tests: instructor-only tests that count for points but show only name, points and pass/fail.

``coursekit grade --hidden-tests DIR`` (and the Gradescope autograder) adds every ``*.py`` file
in DIR. A hidden test file is written like a graded one (tests/exercises/conftest.py's
``student`` / ``sandbox`` fixtures) and declares which exercise it tests and what each test is
worth::

    EXERCISE = "chunk_windows"
    POINTS = {"test_long_episodes": 2, "test_many_short_episodes": 1}

    def test_long_episodes(student): ...

Feedback shows only the name, the points and pass/fail (no hint, message, traceback or output),
so the tests stay secret; ``coursekit check`` (students) never runs them.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

from coursekit.grading.registry import get_exercise


def _constant(tree: ast.Module, name: str, path: Path):
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            try:
                return ast.literal_eval(node.value)
            except ValueError:
                raise ValueError(f"{path}: {name} must be a literal, got {ast.unparse(node.value)!r}") from None
    raise ValueError(f"{path}: a hidden test file must set {name} (see coursekit.grading.hidden)")


def load_hidden_tests(folder: str | Path) -> tuple[dict[str, bytes], dict[str, dict[str, dict[str, float]]]]:
    """(sources: file name -> bytes, points: exercise id -> {file name -> {test -> points}}).

    File names are prefixed with ``hidden_`` so they never collide with the graded test files.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"hidden tests folder {str(folder)!r} does not exist")
    sources: dict[str, bytes] = {}
    points: dict[str, dict[str, dict[str, float]]] = {}
    files = [p for p in sorted(folder.glob("*.py")) if p.name != "conftest.py"]
    if not files:
        raise ValueError(f"hidden tests folder {str(folder)!r} holds no test files (*.py other than conftest.py): "
                         "give a folder of hidden tests or leave out --hidden-tests")
    for path in files:
        data = path.read_bytes()
        tree = _parse(data, path)
        try:
            exercise = get_exercise(str(_constant(tree, "EXERCISE", path)))
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}" if str(path) not in str(exc) else str(exc)) from None
        table = _constant(tree, "POINTS", path)
        functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")}
        if not isinstance(table, dict) or not table:
            raise ValueError(f"{path}: POINTS must map test names to points, got {table!r}")
        for test, value in table.items():
            if test not in functions:
                raise ValueError(f"{path}: POINTS names {test!r}, which is not a test function in the file")
            _check_points(path, test, value)
        name = path.name if path.name.startswith("hidden_") else f"hidden_{path.name}"
        sources[name] = data
        points.setdefault(exercise.id, {})[name] = {t: float(v) for t, v in table.items()}
    return sources, points


def _parse(data: bytes, path: Path) -> ast.Module:
    """The file's syntax tree; ValueError naming the file for bytes that are not UTF-8 or not Python."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}): "
                         "save the hidden test file as UTF-8") from None
    try:
        return ast.parse(text, filename=str(path))
    except SyntaxError as exc:
        raise ValueError(f"{path}: line {exc.lineno}: {exc.msg}") from None


def _check_points(path: Path, test: str, value) -> None:
    """Points must be a finite number > 0 (a bool is not a number of points: True would count as 1)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{path}: points of {test!r} must be a finite number > 0, got {value!r}")
