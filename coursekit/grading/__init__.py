"""Exercises and grading: one marked source, generated stubs/solutions, feedback and a safe grader.

- :mod:`~coursekit.grading.exercises` — the table of exercises (id, chapter, code, points, hints),
  where the course's files are, :func:`load_exercise` (the student's module: ``exercises/`` or,
  with ``COURSEKIT_EXERCISES=solutions``, ``solutions/``).
- :mod:`~coursekit.grading.build` — writes ``exercises/`` (stubs) and ``solutions/`` from the marked code.
- :mod:`~coursekit.grading.notebook` — what a notebook calls: :func:`exercise_or_reference` (the
  student's objects where written, the library's reference, with a banner, where still a stub)
  and ``coursekit.check(id)`` (one exercise's tests, a table of points and hints).
- :mod:`~coursekit.grading.grade` — grades a folder of submissions (``coursekit grade``);
  :mod:`~coursekit.grading.gradescope` writes the Gradescope autograder zip.
- :mod:`~coursekit.grading.report` — one record per test outcome, points and hints, what students
  read (feedback.md, results.json), instructor-only hidden tests.
- The trust boundary: :mod:`~coursekit.grading.trusted` runs the graded tests in a trusted pytest
  process whose tests call student code only through a :mod:`~coursekit.grading.sandbox`
  (deadlines, limits, proxies) -> :mod:`~coursekit.grading.codec` (plain data, never pickle) ->
  :mod:`~coursekit.grading.worker`, an untrusted process started by
  :mod:`~coursekit.grading.bubblewrap` (inside bubblewrap where it works).

Nothing here imports torch or pytest at import time.
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "EXERCISES": "coursekit.grading.exercises:EXERCISES",
    "Exercise": "coursekit.grading.exercises:Exercise",
    "get_exercise": "coursekit.grading.exercises:get_exercise",
    "load_exercise": "coursekit.grading.exercises:load_exercise",
    "exercise_or_reference": "coursekit.grading.notebook:exercise_or_reference",
    "build_exercises": "coursekit.grading.build:build_exercises",
    "grade_submissions": "coursekit.grading.grade:grade_submissions",
}

__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)
