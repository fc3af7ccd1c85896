"""``coursekit.check("<id>")``: instant feedback on one exercise, from a notebook or a terminal.

Runs the exercise's graded tests (never the instructor's hidden ones) in a trusted process that
calls the student's module in a sandboxed worker: the same path as the instructor's grader
(:mod:`coursekit.grading.runner`), so what passes here passes there. Prints::

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

import os
from dataclasses import dataclass
from pathlib import Path

from coursekit.grading.paths import exercise_dir
from coursekit.grading.registry import Exercise, exercise_number, get_exercise
from coursekit.grading.runner import Limits, RunResult, TestScore, run_tests, score_exercise


@dataclass
class CheckResult:
    """Scores of one check; ``print(result.table())`` shows them again."""

    exercise: Exercise
    module: Path
    scores: list[TestScore]
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

    ``directory`` defaults to the folder :func:`coursekit.grading.load_exercise` uses
    (exercises/, or solutions/ with COURSEKIT_EXERCISES=solutions). Save the file (or the
    notebook's %%writefile cell) first: the test subprocess reads the module from disk.
    """
    exercise = get_exercise(exercise_id)
    folder = exercise_dir(directory)
    module = folder / f"{exercise.id}.py"
    if not module.is_file():
        raise FileNotFoundError(f"{module} not found: expected your module for exercise {exercise.id!r} there")
    run = run_tests([exercise], folder, Limits(timeout_s=timeout))
    result = CheckResult(exercise, module, score_exercise(exercise, run), run)
    if show:
        print(result.table())
    return result
