"""What a notebook calls: ``exercise_or_reference`` (the student's code where it is written, the
library's where it is not) and ``coursekit.check`` (instant feedback on one exercise).

Every chapter with an exercise behaves the same way when the exercise is unfinished: one cell
loads it with

    from coursekit.grading import exercise_or_reference
    ex = exercise_or_reference("noise_loss")      # exercise 2.1

and the rest of the chapter uses ``ex.q_sample``, ``ex.epsilon_loss``, ... . For every object
of the exercise (``Exercise.objects``) that is still the generated stub, ``ex`` holds the
library's reference instead and the cell shows a banner:

    exercise 2.1 (noise_loss) not implemented yet: epsilon_loss — the rest of this chapter uses
    the reference (coursekit.diffusion.loss); implement it in exercises/noise_loss.py, then run
    coursekit.check("noise_loss")

so "Run All" on the untouched stubs runs to the end. Once the student fills an object in, the
same cell (re-run) uses the student's version and says so. A half-finished exercise mixes: the
finished objects are the student's, the others the reference's, each named in the banner.

"Still the stub" is decided statically, without running student code: an object is unfinished
while one of its functions (a class's methods included) still holds the generated
``raise NotImplementedError("Exercise N.k (<id>): implement ...")``. Student code that is
written but wrong is used as written: its errors show where they happen, as they should.

New chapters (10, 11, ...) follow the same pattern: one ``exercise_or_reference`` call in the
exercise cell, then pass ``ex.<object>`` explicitly into the library (no monkeypatching), and
``coursekit.check("<id>")`` further down. ``tests/test_notebooks.py`` runs every notebook
against the untouched stubs and requires the banner in every chapter that has an exercise.

``coursekit.check("<id>")`` (``coursekit check <id>`` in a terminal) runs the exercise's graded
tests (never the instructor's hidden ones) in a trusted process that calls the student's module
in a sandboxed worker: the same path as the instructor's grader (:mod:`coursekit.grading.trusted`),
so what passes here passes there. Prints::

    Exercise 1.1 (chunk_windows): Diffusion Policy training windows with edge padding
    module: exercises/chunk_windows.py
      test                                    points  result
      test_shapes_and_dtypes                   0 / 1   FAIL
          hint: Return (indices, episode): int64 arrays of shape (W, Tp) and (W,).
          got:  NotImplementedError: Exercise 1.1 (chunk_windows): implement ...
      ...
    score 0 / 10  (0.9 s)
"""

from __future__ import annotations

import html
import importlib
import os
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coursekit.grading.exercises import Exercise, exercise_dir, exercise_number, get_exercise, load_exercise
from coursekit.grading.report import TestOutcome, score_exercise
from coursekit.grading.sandbox import Limits
from coursekit.grading.trusted import RunResult, run_tests

BANNER_PREFIX = "not implemented yet"
"""Phrase every fallback banner contains (tests look for it in executed notebooks)."""


def _stub_marker(exercise: Exercise) -> str:
    """Start of the message ``coursekit exercises build`` writes into every stub's raise."""
    return f"Exercise {exercise_number(exercise)} ({exercise.id}): implement"


def _code_objects(obj: Any):
    """The code objects of a function, or of every function defined in a class body."""
    if isinstance(obj, type):
        for value in vars(obj).values():
            if isinstance(value, (staticmethod, classmethod)):
                value = value.__func__
            if isinstance(value, property):
                yield from (c for f in (value.fget, value.fset, value.fdel) if f is not None for c in _code_objects(f))
            elif isinstance(value, types.FunctionType):
                yield from _code_objects(value)
        return
    code = getattr(obj, "__code__", None)
    if code is None:
        return
    stack = [code]
    while stack:  # nested functions and comprehensions carry their own code objects
        c = stack.pop()
        yield c
        stack.extend(k for k in c.co_consts if isinstance(k, types.CodeType))


def is_stub(obj: Any, exercise: Exercise) -> bool:
    """True while ``obj`` still raises the generated NotImplementedError of ``exercise``."""
    marker = _stub_marker(exercise)
    return any(isinstance(k, str) and k.startswith(marker) for c in _code_objects(obj) for k in c.co_consts)


@dataclass
class ExerciseParts:
    """One exercise's objects as a chapter should use them: the student's, or the reference's."""

    exercise: Exercise
    """The registry entry (id, chapter, source module, objects)."""
    module: types.ModuleType
    """The student's module as loaded from disk (``load_exercise``)."""
    objects: dict[str, Any]
    """Object name -> the object to use (student's when written, else the library's)."""
    missing: tuple[str, ...] = field(default=())
    """Names still unfinished in the student's module (served by the reference)."""

    @property
    def number(self) -> str:
        return exercise_number(self.exercise)

    @property
    def implemented(self) -> bool:
        """True when every object is the student's own."""
        return not self.missing

    @property
    def __file__(self) -> str:  # noqa: PLW3201 - lets `ex.__file__` work as on a module
        return str(self.module.__file__)

    def __getattr__(self, name: str) -> Any:
        objects = self.__dict__.get("objects", {})
        if name in objects:
            return objects[name]
        module = self.__dict__.get("module")
        if module is not None and hasattr(module, name):
            return getattr(module, name)
        raise AttributeError(f"exercise {self.exercise.id!r} has no object {name!r}; it defines {sorted(objects)}")

    def message(self) -> str:
        """The one-paragraph banner text (plain)."""
        where = _display_path(Path(self.module.__file__))
        if self.implemented:
            return f"exercise {self.number} ({self.exercise.id}): using your {', '.join(self.objects)} from {where}"
        return (f"exercise {self.number} ({self.exercise.id}) {BANNER_PREFIX}: {', '.join(self.missing)} — "
                f"the rest of this chapter uses the reference ({self.exercise.source}); implement "
                f"{'it' if len(self.missing) == 1 else 'them'} in {where}, then run "
                f'coursekit.check("{self.exercise.id}")')

    def _repr_html_(self) -> str:
        ok = self.implemented
        colour, border, mark = ("#e8f5e9", "#2e7d32", "&#10003;") if ok else ("#fff3e0", "#ef6c00", "&#9888;")
        return (f'<div style="background:{colour};border-left:6px solid {border};padding:6px 10px;'
                f'margin:4px 0;font-family:sans-serif;color:#222">{mark} {html.escape(self.message())}</div>')

    def __repr__(self) -> str:
        return ("✓ " if self.implemented else "⚠ ") + self.message()


def _display_path(path: Path) -> str:
    """``exercises/noise_loss.py`` when under the course checkout's cwd or parent, else the full path."""
    for base in (Path.cwd(), Path.cwd().parent):
        try:
            return path.resolve().relative_to(base.resolve()).as_posix()
        except ValueError:
            continue
    return str(path)


def _show(parts: ExerciseParts) -> None:
    """A coloured box in a notebook (text elsewhere), always visible in the cell's output."""
    try:
        from IPython import get_ipython
        from IPython.display import display
    except ImportError:  # plain Python: text only
        print(repr(parts))
        return
    if get_ipython() is None:
        print(repr(parts))
    else:
        display(parts)


def exercise_or_reference(exercise_id: str, directory: str | os.PathLike | None = None, *,
                          show: bool = True) -> ExerciseParts:
    """Load exercise ``exercise_id`` and fill its unfinished objects in from the library.

    Args:
        exercise_id: a registered id, e.g. "noise_loss".
        directory: the student's folder; default as :func:`load_exercise` ($COURSEKIT_EXERCISES).
        show: display the banner (a coloured box in a notebook, one line of text elsewhere).

    Returns:
        An :class:`ExerciseParts`: ``parts.<name>`` is the student's object when written, the
        reference's (``Exercise.source``) while it is still the stub; ``parts.missing`` names the
        latter. The student's module is re-read from disk on every call.
    """
    exercise = get_exercise(exercise_id)
    module = load_exercise(exercise.id, directory)
    reference = importlib.import_module(exercise.source)
    objects, missing = {}, []
    for name in exercise.objects:
        if not hasattr(module, name):
            raise AttributeError(f"{module.__file__} defines no {name!r}: exercise {exercise.id!r} needs "
                                 f"{', '.join(exercise.objects)} (keep the names as they are)")
        theirs = getattr(module, name)
        if is_stub(theirs, exercise):
            objects[name] = getattr(reference, name)
            missing.append(name)
        else:
            objects[name] = theirs
    parts = ExerciseParts(exercise, module, objects, tuple(missing))
    if show:
        _show(parts)
    return parts


# ---------------------------------------------------------------------------- check
@dataclass
class CheckResult:
    """Scores of one check; ``print(result.table())`` shows them again."""

    exercise: Exercise
    module: Path
    """The student's module that was checked."""
    scores: list[TestOutcome]
    """One scored record per graded test."""
    run: RunResult

    @property
    def points(self) -> float:
        return sum(s.points for s in self.scores)

    @property
    def max_points(self) -> float:
        return sum(s.max_points for s in self.scores)

    @property
    def all_passed(self) -> bool:
        return all(s.passed for s in self.scores)

    def table(self) -> str:
        e = self.exercise
        width = max(len(s.name) for s in self.scores) + 2
        lines = [f"Exercise {exercise_number(e)} ({e.id}): {e.title}", f"module: {self.module}"]
        if self.run.status != "ok":
            lines.append(f"!! {self.run.reason}")
        lines.append(f"  {'test':<{width}}{'points':>9}  result")
        for s in self.scores:
            mark = "pass" if s.passed else "FAIL"
            lines.append(f"  {s.name:<{width}}{s.points:>4g} / {s.max_points:<3g} {mark}")
            if not s.passed:
                lines.append(f"      hint: {s.hint}")
                if s.message:
                    lines.append(f"      got:  {s.message}")
        lines.append(f"score {self.points:g} / {self.max_points:g}  ({self.run.seconds:.1f} s)")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"CheckResult({self.exercise.id}: {self.points:g} / {self.max_points:g})"


def check(exercise_id: str, directory: str | os.PathLike | None = None, *, timeout: float = 120.0,
          show: bool = True) -> CheckResult:
    """Run the graded tests of ``exercise_id`` on the student's module and print a table.

    ``directory`` defaults to the folder :func:`coursekit.grading.exercises.load_exercise` uses
    (exercises/, or solutions/ with COURSEKIT_EXERCISES=solutions). Save the file (or the
    notebook's %%writefile cell) first: the test subprocess reads the module from disk.
    """
    exercise = get_exercise(exercise_id)
    folder = exercise_dir(directory)
    module = folder / f"{exercise.id}.py"
    if not module.is_file():
        raise FileNotFoundError(f"{module} not found: expected your module for exercise {exercise.id!r} there")
    run = run_tests([exercise], folder, Limits(timeout_s=timeout))
    result = CheckResult(exercise, module, score_exercise(exercise, run.outcomes, run.reason), run)
    if show:
        print(result.table())
    return result
