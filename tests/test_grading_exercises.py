"""CI requirement: every graded test passes on solutions/ and FAILS on the untouched exercises/.

Both folders are graded through the real runner (one sandboxed subprocess per folder for all
registered exercises), so this also checks that the harness reports every collected test.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from coursekit.grading.exercises import EXERCISES, repo_root
from coursekit.grading.report import score_exercise
from coursekit.grading.sandbox import Limits
from coursekit.grading.trusted import run_tests

LIMITS = Limits(timeout_s=300, test_timeout_s=60)
pytestmark = pytest.mark.slow  # two subprocesses that import torch: ~10-25 s on 2 busy cores


@pytest.fixture(scope="module")
def runs():
    root = repo_root()
    kinds = ("solutions", "exercises")
    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(lambda kind: run_tests(list(EXERCISES), root / kind, LIMITS), kinds))
    return dict(zip(kinds, results))


@pytest.mark.parametrize("exercise", EXERCISES, ids=lambda e: e.id)
def test_every_graded_test_passes_on_solutions(runs, exercise):
    run = runs["solutions"]
    assert run.status == "ok", f"{run.reason}\n{run.log_tail}"
    failed = [(s.name, s.message) for s in score_exercise(exercise, run.outcomes, run.reason) if not s.passed]
    assert not failed, f"{exercise.id} on solutions/: {failed}"


@pytest.mark.parametrize("exercise", EXERCISES, ids=lambda e: e.id)
def test_every_graded_test_fails_on_untouched_stubs(runs, exercise):
    run = runs["exercises"]
    assert run.status == "ok", f"{run.reason}\n{run.log_tail}"
    scores = score_exercise(exercise, run.outcomes, run.reason)
    cases = [o for o in run.outcomes if o.file == f"test_{exercise.id}.py"]
    assert cases and all(o.outcome == "failed" for o in cases), (
        f"{exercise.id}: these tests pass on the stub, so they check nothing: "
        f"{[o.name for o in cases if o.outcome != 'failed']}")
    assert sum(s.points for s in scores) == 0
