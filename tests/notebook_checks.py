"""What every executed course notebook must show, wherever it ran (nbclient in tests/test_notebooks.py,
JupyterLab in tests/test_browser_lab.py): no error output, and each of its chapter's exercises
announcing which implementation it uses. Works on nbformat nodes and on plain notebook JSON."""

from __future__ import annotations


def outputs_text(nb) -> str:
    """All text a reader sees in the executed notebook's outputs (streams, text/plain, text/html)."""
    parts = []
    for cell in nb["cells"]:
        for out in cell.get("outputs", []):
            parts.append(out.get("text", ""))
            data = out.get("data", {})
            parts += [data.get("text/plain", ""), data.get("text/html", "")]
    return "\n".join(p if isinstance(p, str) else "".join(p) for p in parts)


def banner_problems(nb, chapter: int, mode: str) -> list[str]:
    """Exercises of ``chapter`` whose banner is wrong for ``mode`` ("solutions" or "exercises"):
    with the stubs each must say it is not implemented yet, with the solutions each must say it
    uses the student's code."""
    from coursekit.grading import EXERCISES
    from coursekit.grading.exercises import exercise_number
    from coursekit.grading.notebook import BANNER_PREFIX

    text, problems = outputs_text(nb), []
    for exercise in (e for e in EXERCISES if e.chapter == chapter):
        label = f"exercise {exercise_number(exercise)} ({exercise.id})"
        unfinished = f"{label} {BANNER_PREFIX}" in text
        if mode == "exercises" and not unfinished:
            problems.append(f"no 'not implemented yet' banner for the unfinished exercise {exercise.id!r}")
        if mode == "solutions" and (unfinished or f"{label}: using your" not in text):
            problems.append(f"exercise {exercise.id!r} does not say it uses the solution")
    return problems
