"""What a student reads: feedback.md and Gradescope's results.json for one graded submission.

For each failing test: the hint chosen by what failed (:func:`coursekit.grading.scoring.choose_hint`),
what happened in one line, and the traceback and printed output. A traceback shared by several
tests (a NotImplementedError, an import error) is shown once, the other tests point to it.
Hidden tests show only name, points and pass/fail. Paths of the instructor's machine never
appear (the runner scrubs them).
"""

from __future__ import annotations

from coursekit.grading.registry import exercise_number
from coursekit.grading.scoring import TestScore


def _shared(scores: list[TestScore]) -> dict[int, str]:
    """index of a failing test -> name of the earlier test showing the same traceback."""
    first_by_detail: dict[str, str] = {}
    out = {}
    for i, s in enumerate(scores):
        if s.passed or s.hidden or not s.detail:
            continue
        if s.detail in first_by_detail:
            out[i] = first_by_detail[s.detail]
        else:
            first_by_detail[s.detail] = s.name
    return out


def _test_output(score: TestScore, same_as: str = "") -> str:
    if score.passed:
        return "passed"
    if score.hidden:
        return "failed (hidden test)"
    parts = [f"hint: {score.hint}"]
    if score.message:
        parts.append(f"what happened: {score.message}")
    if score.detail:
        parts.append(f"traceback: the same as in {same_as}" if same_as else "traceback (tail):\n" + score.detail)
    if score.output:
        parts.append("your code printed (tail):\n" + score.output)
    return "\n".join(parts)


def gradescope_json(student) -> dict:
    """Gradescope autograder results (https://gradescope-autograders.readthedocs.io, results.json)."""
    tests = []
    for g in student.grades:
        number = exercise_number(g.exercise)
        shared = _shared(g.scores)
        for i, s in enumerate(g.scores, start=1):
            same = shared.get(i - 1, "")
            tests.append({
                "name": f"{number} {g.exercise.id}: {s.name}" + (" (hidden)" if s.hidden else ""),
                "number": f"{number}.{i}",
                "score": s.points,
                "max_score": s.max_points,
                "status": "passed" if s.passed else "failed",
                "output": _test_output(s, f"{number} {g.exercise.id}: {same}" if same else ""),
                "visibility": "visible",
            })
    notes = [f"{g.exercise.id}: {g.reason}" for g in student.grades if g.reason]
    if student.problem:
        notes.insert(0, student.problem)
    return {
        "score": student.points,
        "output": f"coursekit autograder: {student.points:g} / {student.max_points:g} points" + "".join(f"\n- {n}" for n in notes),
        "visibility": "visible",
        "stdout_visibility": "hidden",
        "tests": tests,
    }


def feedback_markdown(student) -> str:
    """A readable per-student report."""
    lines = [f"# Feedback for {student.student}", "", f"Total: **{student.points:g} / {student.max_points:g}**", ""]
    if student.problem:
        lines += [f"Problem with the submission: {student.problem}", ""]
    for g in student.grades:
        e = g.exercise
        lines += [f"## Exercise {exercise_number(e)} ({e.id}): {e.title} — {g.points:g} / {g.max_points:g}", ""]
        if g.reason:
            lines += [f"**Note:** {g.reason}", ""]
        lines += ["| test | points | result |", "|---|---|---|"]
        lines += [f"| `{s.name}`{' (hidden)' if s.hidden else ''} | {s.points:g} / {s.max_points:g} | "
                  f"{'pass' if s.passed else 'FAIL'} |" for s in g.scores]
        lines.append("")
        shared = _shared(g.scores)
        for i, s in enumerate(g.scores):
            if s.passed or s.hidden:
                continue
            lines += [f"### `{s.name}`", "", f"- hint: {s.hint}"]
            if s.message:
                lines.append(f"- what happened: `{s.message.replace('`', chr(39))}`")
            if s.detail and i in shared:
                lines.append(f"- traceback: the same as in `{shared[i]}` above")
            elif s.detail:
                lines += ["", "```", s.detail.replace("```", "'''"), "```"]
            if s.output:
                lines += ["", "Your code printed (tail):", "", "```", s.output.replace("```", "'''"), "```"]
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"
