"""Points, status and hints from the outcomes of one trusted test run.

A registered test scores ``points x passed cases / cases`` (parametrised tests give partial
credit). The hint shown for a failing test is chosen by WHAT failed (:func:`choose_hint`): the
student's code raised, timed out or crashed (fix that first; the maths hint comes second), or a
comparison failed on a shape, a dtype, a type or the values (the registry's hint for that test,
or its per-kind hint when the registry gives one). Hidden tests (:mod:`coursekit.grading.hidden`)
count for points but carry no hint, message or traceback.
"""

from __future__ import annotations

from dataclasses import dataclass

from coursekit.grading.registry import Exercise

# leads for failures where the maths hint is not the first thing to look at
LEADS = {
    "error": "Your code raised an exception (see 'what happened' and the traceback); fix that first.",
    "timeout": "Your code did not return in time: look for an endless loop or a very slow path.",
    "crashed": "The process running your code ended (os._exit, sys.exit, a crash): don't exit from exercise code.",
    "memory": "Your code used too much memory: avoid huge temporary arrays.",
    "output": "Your code printed too much: remove prints inside loops.",
    "reference": "Your code calls the library's reference implementation (or solutions/): write your own.",
    "protocol": "Your code returned something that cannot be sent back to the grader (plain arrays, tensors, numbers).",
    "shape": "Wrong shape:",
    "dtype": "Wrong dtype:",
    "type": "Wrong type of result:",
}
STATUS_ORDER = ("reference", "timeout", "memory", "output", "crashed", "protocol")
"""An exercise's status is the first of these causes that occurred in any of its tests, else "ok"."""


@dataclass
class TestScore:
    """Points for one graded test function of an exercise."""

    name: str
    points: float
    max_points: float
    passed: bool
    hint: str
    message: str = ""
    detail: str = ""
    output: str = ""
    kind: str = ""
    """What failed first (see :class:`coursekit.grading.runner.Outcome`); "" when passed."""
    hidden: bool = False
    """An instructor-only test: feedback shows name, points and pass/fail only."""


def choose_hint(exercise: Exercise, test: str, kind: str, message: str = "") -> str:
    """The hint for ``test`` of ``exercise`` that failed with ``kind`` (``message``: what happened)."""
    spec = exercise.tests[test]
    base = spec[1]
    per_kind = spec[2] if len(spec) > 2 else {}
    if kind in per_kind:
        return per_kind[kind]
    if kind == "error" and "NotImplementedError" in message:
        return base  # an unfinished stub: the maths is the hint
    lead = LEADS.get(kind, "")
    return f"{lead} {base}".strip() if lead else base


def exercise_status(exercise: Exercise, outcomes) -> str:
    """"ok", or the most serious worker failure among the exercise's tests (see STATUS_ORDER)."""
    causes = {o.cause for o in outcomes}
    return next((c for c in STATUS_ORDER if c in causes), "ok")


def _by_function(outcomes, file: str) -> dict[str, list]:
    out: dict[str, list] = {}
    for outcome in outcomes:
        if outcome.file == file:
            out.setdefault(outcome.function, []).append(outcome)
    return out


def score_exercise(exercise: Exercise, run, hidden: dict[str, dict[str, float]] | None = None) -> list:
    """Points per registered test (and per hidden test: ``hidden`` maps file -> {test: points})."""
    scores = []
    specs = [(f"test_{exercise.id}.py", name, spec[0], False) for name, spec in exercise.tests.items()]
    for file, tests in sorted((hidden or {}).items()):
        specs += [(file, name, points, True) for name, points in tests.items()]
    grouped = {}
    for file, name, max_points, is_hidden in specs:
        if file not in grouped:
            grouped[file] = _by_function(run.outcomes, file)
        cases = grouped[file].get(name, [])
        passed = sum(o.outcome == "passed" for o in cases)
        points = max_points * passed / len(cases) if cases else 0.0
        failed = [o for o in cases if o.outcome != "passed"]
        first = failed[0] if failed else None
        kind = first.kind if first else ("error" if not cases else "")
        if not cases:
            message = run.reason or "the test was not found in the test run"
        elif failed:
            label = f"{len(failed)}/{len(cases)} cases failed; first: " if len(cases) > 1 else ""
            message = label + (first.message or first.outcome)
        else:
            message = ""
        hint = "" if is_hidden else (choose_hint(exercise, name, kind, message) if (failed or not cases) else exercise.tests[name][1])
        score = TestScore(name=name, points=round(points, 6), max_points=float(max_points),
                          passed=bool(cases) and not failed, hint=hint, message=message,
                          detail=first.detail if first else "", output=first.output if first else "", kind=kind,
                          hidden=is_hidden)
        if is_hidden:
            score.message = score.detail = score.output = ""
        scores.append(score)
    return scores
