"""Exercises and grading: one marked source, generated stubs/solutions, feedback and a safe grader.

- :mod:`coursekit.grading.registry` — the table of exercises (id, chapter, code, points, hints).
- :mod:`coursekit.grading.build` — writes ``exercises/`` (stubs) and ``solutions/`` from the marked code.
- :func:`load_exercise` — the student's module (``exercises/`` or, with
  ``COURSEKIT_EXERCISES=solutions``, ``solutions/``).
- :func:`exercise_or_reference` (:mod:`coursekit.grading.fallback`) — what a notebook uses: the
  student's objects where written, the library's reference (with a banner) where still a stub.
- ``coursekit.check(id)`` (:mod:`coursekit.grading.check`) — runs one exercise's tests in a
  subprocess and prints a table (notebooks).
- :mod:`coursekit.grading.grade` — grades a folder of submissions (``coursekit grade``);
  :mod:`~coursekit.grading.feedback` writes what students read, :mod:`~coursekit.grading.gradescope`
  the autograder zip, :mod:`~coursekit.grading.hidden` reads instructor-only tests.
- The trust boundary: :mod:`~coursekit.grading.runner` starts a trusted pytest process
  (:mod:`~coursekit.grading.harness`) whose tests call student code only through
  :mod:`~coursekit.grading.remote` -> :mod:`~coursekit.grading.protocol` (plain data, never
  pickle) -> :mod:`~coursekit.grading.worker`, an untrusted process started by
  :mod:`~coursekit.grading.sandbox` (bubblewrap where it works); :mod:`~coursekit.grading.scoring`
  turns outcomes into points and hints.

Nothing here imports torch or pytest at import time.
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "EXERCISES": "coursekit.grading.registry:EXERCISES",
    "Exercise": "coursekit.grading.registry:Exercise",
    "get_exercise": "coursekit.grading.registry:get_exercise",
    "load_exercise": "coursekit.grading.loader:load_exercise",
    "exercise_or_reference": "coursekit.grading.fallback:exercise_or_reference",
    "build_exercises": "coursekit.grading.build:build_exercises",
    "grade_submissions": "coursekit.grading.grade:grade_submissions",
}

__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)
