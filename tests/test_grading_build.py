"""exercises/ and solutions/ are exactly what `coursekit exercises build` writes, and the generator
turns marked code into stubs and solutions (and refuses malformed markers)."""

from __future__ import annotations

import ast
import textwrap

import pytest

from coursekit.cli import main
from coursekit.grading.build import build_exercises, expected_files, render_exercise
from coursekit.grading.exercises import EXERCISES, Exercise, repo_root


def test_committed_folders_match_a_fresh_build():
    stale = build_exercises(check=True)
    assert stale == [], f"run `coursekit exercises build` and commit: {[str(p) for p in stale]}"


def test_build_is_deterministic_and_writes_only_differences(tmp_path):
    assert build_exercises(tmp_path) != []  # empty root: everything is written
    first = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert build_exercises(tmp_path) == []  # second build: nothing to do
    assert {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == first
    root = repo_root()
    for rel, data in first.items():
        assert (root / rel).read_bytes() == data, f"{rel} differs from the committed file"


def test_cli_check_mode_reports_a_stale_file(tmp_path, capsys):
    build_exercises(tmp_path)
    edited = tmp_path / "exercises" / f"{EXERCISES[0].id}.py"
    edited.write_text(edited.read_text() + "# edited by hand\n")  # keeps its header: the build may restore it
    assert main(["exercises", "build", "--check", "--root", str(tmp_path)]) == 1
    assert "differs from a fresh build" in capsys.readouterr().out
    assert main(["exercises", "build", "--root", str(tmp_path)]) == 0
    assert main(["exercises", "build", "--check", "--root", str(tmp_path)]) == 0


@pytest.mark.parametrize("exercise", EXERCISES, ids=lambda e: e.id)
def test_stub_and_solution_are_valid_python_with_the_same_signatures(exercise):
    stub, solution = render_exercise(exercise, "exercises"), render_exercise(exercise, "solutions")
    assert "BEGIN SOLUTION" not in stub + solution and "END SOLUTION" not in stub + solution
    assert "raise NotImplementedError" in stub
    stub_tree, sol_tree = ast.parse(stub), ast.parse(solution)
    names = lambda tree: [n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))]  # noqa: E731
    assert names(stub_tree) == names(sol_tree) == list(exercise.objects)
    for a, b in zip(stub_tree.body, sol_tree.body):
        if isinstance(a, (ast.FunctionDef, ast.ClassDef)):
            assert ast.get_docstring(a) == ast.get_docstring(b) and ast.get_docstring(a), "stub keeps the docstring"
            if isinstance(a, ast.FunctionDef):
                assert ast.dump(a.args) == ast.dump(b.args)


def _fake_exercise(tmp_path, monkeypatch, body: str, name: str) -> Exercise:
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(body))
    monkeypatch.syspath_prepend(str(tmp_path))
    return Exercise(id="fake", chapter=9, title="fake", source=name, objects=("f",), tests={"test_x": (1, "hint")})


def test_generator_replaces_blocks_and_adds_imports(tmp_path, monkeypatch):
    exercise = _fake_exercise(tmp_path, monkeypatch, '''
        from __future__ import annotations
        import math
        import os

        SCALE = 2.0


        def _helper(x):
            return x


        class Unused:
            pass


        def f(x: float) -> float:
            """Doubles: f(x) = SCALE * sqrt(x)**2."""
            if x < 0:
                raise ValueError(x)
            # BEGIN SOLUTION
            y = SCALE * _helper(math.sqrt(x)) ** 2
            # END SOLUTION
            return y
        ''', "ck_fake_ok")
    stub, solution = render_exercise(exercise, "exercises"), render_exercise(exercise, "solutions")
    for text in (stub, solution):
        assert "import math\n" in text and "import os" not in text and "Unused" not in text
        assert "from ck_fake_ok import SCALE, _helper" in text
        assert "from __future__ import annotations" in text
    assert "raise NotImplementedError('Exercise 9.1 (fake): implement f; see its docstring')" in stub
    assert "y = SCALE" not in stub and "raise ValueError(x)" in stub
    namespace: dict = {}
    exec(compile(solution, "solution", "exec"), namespace)
    assert namespace["f"](4.0) == pytest.approx(8.0)


@pytest.mark.parametrize("body, error", [
    ("def f():\n    return 1\n", "no '# BEGIN SOLUTION'"),
    ("def f():\n    # BEGIN SOLUTION\n    return 1\n", "has no"),
    ("def f():\n    return 1\n    # END SOLUTION\n", "without"),
    ("def f():\n    # BEGIN SOLUTION\n    # BEGIN SOLUTION\n    x = 1\n    # END SOLUTION\n", "nested"),
    ("def f():\n    if True:\n        # BEGIN SOLUTION\n        x = 1\n    # END SOLUTION\n", "indented differently"),
    ("def g():\n    pass\n", "no module-level function or class 'f'"),
])
def test_generator_refuses_malformed_markers(tmp_path, monkeypatch, body, error):
    name = f"ck_fake_bad_{abs(hash(body)) % 10**8}"
    exercise = _fake_exercise(tmp_path, monkeypatch, body, name)
    with pytest.raises(ValueError, match=error):
        render_exercise(exercise, "exercises")


def test_readme_lists_every_exercise():
    for kind in ("exercises", "solutions"):
        readme = expected_files(kind)["README.md"]
        for exercise in EXERCISES:
            assert f"`{exercise.id}`" in readme
