"""Graded exercise tests: every module here tests the STUDENT's implementation of one exercise.

Which implementation is tested is chosen by $COURSEKIT_EXERCISES: "exercises" (the stubs, or
the student's work), "solutions", or a path (the grader points it at a scratch copy of a
submission). Without it these modules are not collected: the main suite checks them through
tests/test_grading_exercises.py (solutions pass, untouched stubs fail), and students use
``coursekit.check("<id>")``. Each test module sets ``EXERCISE = "<id>"``; its tests take the
``student`` fixture (the loaded module) and compare it with a trusted reference.
"""

from __future__ import annotations

import os

import pytest

from coursekit.grading.loader import load_exercise

if not os.environ.get("COURSEKIT_EXERCISES"):
    collect_ignore_glob = ["test_*.py"]


@pytest.fixture(scope="module")
def student(request):
    """The module under test: ``<folder>/<EXERCISE>.py`` (import errors fail every test of the module)."""
    return load_exercise(request.module.EXERCISE)
