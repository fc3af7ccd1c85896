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
import re
import shutil
import tempfile
import threading
import time
from pathlib import Path

import pytest

from coursekit.grading.exercises import exercise_dir, repo_root
from coursekit.grading.sandbox import Limits, RemoteModule, Sandbox
from coursekit.grading.trusted import grading_settings

if not os.environ.get("COURSEKIT_EXERCISES"):
    collect_ignore_glob = ["test_*.py"]

EARLY = pytest.StashKey[dict]()
"""config.stash key: test module path -> its :class:`EarlyWorker`, started at session start."""


def _sends_tensors(exercise_id: str) -> bool:
    """Whether the exercise's test module imports torch (its worker then preloads it)."""
    text = (Path(__file__).parent / f"test_{exercise_id}.py").read_text(encoding="utf-8")
    return re.search(r"^(import torch|from torch\b)", text, re.M) is not None


def new_sandbox(config, exercise_id: str, scratch) -> Sandbox:
    """The worker of one exercise, with the grading run's limits (defaults outside the grader)."""
    settings = grading_settings(config) or {}
    folder = settings.get("submission") or str(exercise_dir())
    limits = Limits(timeout_s=float(settings.get("budget", 600)), test_timeout_s=float(settings.get("test_timeout", 60)),
                    memory_mb=int(settings.get("memory_mb", 2048)), output_mb=int(settings.get("file_mb", 32)),
                    disk_mb=int(settings.get("disk_mb", 64)))
    return Sandbox(exercise_id, folder, scratch, limits, mode=settings.get("mode"),
                   solutions_dir=settings.get("solutions_dir") or str(repo_root() / "solutions"),
                   tag=settings.get("tag", ""), reap=bool(settings),
                   preload=("torch",) if _sends_tensors(exercise_id) else ())


class EarlyWorker:
    """A test module's worker started in a thread at session start, so that its start-up (importing
    torch) runs while this process imports the test modules (torch again) instead of after them: on
    two cores, most of the wait of ``coursekit.check``. The thread stays alive until :meth:`close`:
    the worker dies with the thread that started it (bwrap --die-with-parent is PR_SET_PDEATHSIG,
    which fires when that thread ends)."""

    def __init__(self, config, exercise_id: str) -> None:
        # not under --basetemp: pytest empties that folder when it first uses it
        self.scratch = tempfile.mkdtemp(prefix="coursekit-worker-")
        self.started, self.closing = threading.Event(), threading.Event()
        try:
            self.box: Sandbox | None = new_sandbox(config, exercise_id, self.scratch)
        except Exception:  # noqa: BLE001 - the fixture builds it again and reports the error there
            self.box = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        # Wait (sleeping) until the worker process exists AND has its settings: this thread goes on
        # to import the test modules, and torch's import holds the GIL for long stretches. Waiting only
        # for the process left the settings unsent until torch was in: the worker then sat idle and
        # imported torch after this process instead of beside it (about 2.5 s of every check).
        deadline = time.monotonic() + 5.0
        while self.box is not None and not self.box.launched and not self.started.is_set() \
                and time.monotonic() < deadline:
            time.sleep(0.005)

    def _run(self) -> None:
        try:
            if self.box is not None:
                self.box.prestart()
        finally:
            self.started.set()
        self.closing.wait()

    def take(self) -> Sandbox | None:
        """The started sandbox (None if building it failed: the caller builds one itself)."""
        self.started.wait()
        return self.box

    def close(self) -> None:
        self.started.wait()
        if self.box is not None:
            self.box.close()
        self.closing.set()
        self.thread.join()
        shutil.rmtree(self.scratch, ignore_errors=True)


def pytest_sessionstart(session):
    """Start the worker of the first graded module named on the command line (see :class:`EarlyWorker`).
    Only the first: pytest imports every module before the first test, so only that worker's start-up
    can overlap the imports; the others start when their module runs, after the previous worker has
    gone (a closing sandbox also ends every other process the grader left, ``kill_orphans``)."""
    from coursekit.grading import EXERCISES

    if not os.environ.get("COURSEKIT_EXERCISES"):
        return
    ids = {e.id for e in EXERCISES}
    for arg in session.config.args:
        path = Path(arg).resolve()
        exercise = path.stem.removeprefix("test_")
        if path.parent == Path(__file__).resolve().parent and path.suffix == ".py" and exercise in ids:
            session.config.stash[EARLY] = {str(path): EarlyWorker(session.config, exercise)}
            return


def pytest_sessionfinish(session):
    """Workers started early for modules that never ran (deselected, failed to import) stop here."""
    for worker in session.config.stash.get(EARLY, {}).values():
        worker.close()


@pytest.fixture(scope="module")
def sandbox(request, tmp_path_factory):
    """The worker for this module's exercise (restarted by itself after a crash or a timeout)."""
    early = request.config.stash.get(EARLY, {}).pop(str(Path(request.module.__file__).resolve()), None)
    box = early.take() if early is not None else None
    if box is None or box.exercise.id != request.module.EXERCISE:
        if early is not None:
            early.close()
        early = None
        box = new_sandbox(request.config, request.module.EXERCISE, tmp_path_factory.mktemp("worker"))
    yield box
    if early is not None:
        early.close()
    else:
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
