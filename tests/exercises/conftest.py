"""Graded exercise tests: every module here tests the STUDENT's implementation of one exercise.

The student's code never runs in this (trusted) process. Each test module sets
``EXERCISE = "<id>"`` and takes two fixtures:

- ``student``: the student's module as a proxy; ``student.f(args)`` runs ``f`` in an untrusted
  worker (sandboxed with bubblewrap where available) and returns plain data: numpy arrays,
  plain torch tensors, numbers, strings, lists, dicts. Objects stay in the worker as handles
  (call them, read attributes). Functions of the test passed in stay here (the worker calls back).
- ``sandbox``: ``seed``, ``new`` (a coursekit object built in the worker), ``parameters``,
  ``state_dict``, ``load_state_dict``, ``grad`` (gradients computed in the worker).

Every comparison is written here, against a trusted reference. A test of one function uses the
reference (never the student's version) for every other function it needs, so one wrong
function fails only its own tests. Which implementation is graded is chosen by
$COURSEKIT_EXERCISES ("exercises", "solutions" or a path; the grader sets it per submission).
Without it these modules are not collected: the main suite checks them through
tests/test_grading_exercises.py, and students use ``coursekit.check("<id>")``.
"""

from __future__ import annotations

import os

import pytest

from coursekit.grading.exercises import exercise_dir, repo_root
from coursekit.grading.sandbox import Limits, RemoteModule, Sandbox
from coursekit.grading.trusted import grading_settings

if not os.environ.get("COURSEKIT_EXERCISES"):
    collect_ignore_glob = ["test_*.py"]


@pytest.fixture(scope="module")
def sandbox(request, tmp_path_factory):
    """The worker for this module's exercise (restarted by itself after a crash or a timeout)."""
    settings = grading_settings(request.config) or {}
    folder = settings.get("submission") or str(exercise_dir())
    limits = Limits(timeout_s=float(settings.get("budget", 600)), test_timeout_s=float(settings.get("test_timeout", 60)),
                    memory_mb=int(settings.get("memory_mb", 2048)), output_mb=int(settings.get("file_mb", 32)),
                    disk_mb=int(settings.get("disk_mb", 64)))
    box = Sandbox(request.module.EXERCISE, folder, tmp_path_factory.mktemp("worker"), limits, mode=settings.get("mode"),
                  solutions_dir=settings.get("solutions_dir") or str(repo_root() / "solutions"),
                  tag=settings.get("tag", ""), reap=bool(settings))
    yield box
    box.close()


@pytest.fixture(scope="module")
def student(sandbox):
    """The student's module: ``student.<name>(...)`` runs in the worker, results come back as plain data."""
    return RemoteModule(sandbox)


@pytest.fixture(autouse=True)
def _deadline_and_output(request):
    """Each test gets the per-test timeout; what the student's code printed is kept for the feedback."""
    uses = {"student", "sandbox"} & set(request.fixturenames)
    box = request.getfixturevalue("sandbox") if uses else None
    if box is not None:
        box.start_test()
    yield
    if box is not None:
        request.node.user_properties.append(("student_output", box.output_tail()))
