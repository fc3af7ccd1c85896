"""``coursekit grade``: grade a folder of submissions safely and write the class's results.

Layout of ``SUBMISSIONS_DIR``: one entry per student, either a folder (a copy of the handed-out
``exercises/``; the modules may also sit one folder down) or a ``.zip`` of it. The student id is
the folder name or the zip's stem. For every student and exercise one sandboxed subprocess runs
the graded tests (:func:`coursekit.grading.runner.run_tests`); the test files are read once at
the start, so nothing a submission does to files on disk changes how the others are graded.

Written to ``--out`` (each file atomically, as soon as it is complete; contents deterministic:
no timestamps or timings)::

    grades.csv                 student x exercise points, total, max, notes
    <student>/results.json     Gradescope format: score, tests[name, number, score, max_score, status, output]
    <student>/feedback.md      readable feedback: per test points, hint and what went wrong
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import re
import tempfile
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from coursekit.grading.paths import repo_root
from coursekit.grading.registry import EXERCISES, Exercise, exercise_number, get_exercise
from coursekit.grading.runner import Limits, RunResult, TestScore, read_test_sources, run_tests, score_exercise
from coursekit.atomic import atomic_write_text

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


@dataclass
class ExerciseGrade:
    """One student's result on one exercise."""

    exercise: Exercise
    scores: list[TestScore]
    status: str
    """"ok", "missing", "timeout", "memory", "crashed", "tampered" or "error"."""
    reason: str = ""

    @property
    def points(self) -> float:
        return round(sum(s.points for s in self.scores), 6)


@dataclass
class StudentGrade:
    student: str
    grades: list[ExerciseGrade] = field(default_factory=list)
    problem: str = ""
    """Why the submission itself could not be read (bad zip, ...), if so."""

    @property
    def points(self) -> float:
        return round(sum(g.points for g in self.grades), 6)


@dataclass
class GradeSummary:
    students: list[StudentGrade]
    exercises: list[Exercise]
    out: Path
    seconds: float
    warnings: list[str] = field(default_factory=list)


def _student_id(name: str, taken: set[str]) -> str:
    base = _SAFE.sub("_", name).strip("._") or "student"
    candidate, i = base, 2
    while candidate in taken:
        candidate, i = f"{base}_{i}", i + 1
    taken.add(candidate)
    return candidate


def discover(submissions: Path, out: Path | None = None) -> list[tuple[str, Path]]:
    """(student id, folder or zip) for every submission, sorted by name (``out`` is skipped)."""
    if not submissions.is_dir():
        raise FileNotFoundError(f"submissions folder {str(submissions)!r} does not exist")
    skip = out.resolve() if out is not None else None
    entries = [p for p in sorted(submissions.iterdir()) if not p.name.startswith(".")
               and (p.is_dir() or p.suffix.lower() == ".zip") and p.resolve() != skip]
    taken: set[str] = {"grades.csv"}  # never collide with the class CSV
    return [(_student_id(p.stem if p.is_file() else p.name, taken), p) for p in entries]


def _module_folder(root: Path, exercises: list[Exercise]) -> Path:
    """The folder holding the modules: ``root`` or, if only there, one folder down."""
    names = {f"{e.id}.py" for e in exercises}
    if any((root / n).is_file() for n in names):
        return root
    for sub in sorted(p for p in root.iterdir() if p.is_dir() and not p.is_symlink()):
        if any((sub / n).is_file() for n in names):
            return sub
    return root


def _extract_zip(archive: Path, dest: Path, exercises: list[Exercise]) -> None:
    """Copy only ``<id>.py`` members (any folder depth, size-capped) out of ``archive`` into ``dest``."""
    from coursekit.grading.runner import MAX_MODULE_BYTES

    wanted = {f"{e.id}.py" for e in exercises}
    with zipfile.ZipFile(archive) as zf:
        members = sorted(zf.infolist(), key=lambda m: (m.filename.count("/"), m.filename))
        for member in members:
            name = member.filename.rsplit("/", 1)[-1]
            if member.is_dir() or name not in wanted or (dest / name).exists() or "__MACOSX" in member.filename:
                continue
            if member.file_size > MAX_MODULE_BYTES:
                continue
            with zf.open(member) as fh:
                data = fh.read(MAX_MODULE_BYTES + 1)
            if len(data) <= MAX_MODULE_BYTES:
                (dest / name).write_bytes(data)


def _grade_one(exercise: Exercise, folder: Path, limits: Limits, sources: dict[str, bytes]) -> ExerciseGrade:
    module = folder / f"{exercise.id}.py"
    if not module.is_file():
        run = RunResult(status="missing", reason=f"{exercise.id}.py was not found in the submission")
        return ExerciseGrade(exercise, score_exercise(exercise, run), run.status, run.reason)
    run = run_tests([exercise], folder, limits, sources)
    return ExerciseGrade(exercise, score_exercise(exercise, run), run.status, run.reason)


def _fingerprint(root: Path, exercises: list[Exercise]) -> dict[str, str]:
    """Hashes of the files grading trusts: graded tests, conftest and the reference modules."""
    import importlib.util

    paths = [root / "tests" / "exercises" / "conftest.py"] + [root / e.test_module for e in exercises]
    for e in exercises:
        spec = importlib.util.find_spec(e.source)
        if spec is not None and spec.origin:
            paths.append(Path(spec.origin))
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "missing" for p in paths}


def grade_submissions(submissions: str | Path, out: str | Path, exercises: list[str] | None = None,
                      jobs: int = 1, limits: Limits | None = None, progress: bool = True) -> GradeSummary:
    """Grade every submission in ``submissions`` and write the results under ``out``."""
    if int(jobs) < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs!r}")
    start = time.monotonic()
    limits = limits or Limits()
    chosen = [get_exercise(e) for e in exercises] if exercises else list(EXERCISES)
    submissions, out = Path(submissions), Path(out)
    entries = discover(submissions, out)
    root = repo_root()
    sources = read_test_sources(chosen, root)
    before = _fingerprint(root, chosen)
    students = {sid: StudentGrade(sid) for sid, _ in entries}

    with tempfile.TemporaryDirectory(prefix="coursekit-submissions-") as unpack:
        tasks = []
        for sid, path in entries:
            folder = path
            if path.is_file():
                folder = Path(unpack) / sid
                folder.mkdir()
                try:
                    _extract_zip(path, folder, chosen)
                except (zipfile.BadZipFile, OSError, ValueError, NotImplementedError) as exc:
                    students[sid].problem = f"could not read {path.name}: {type(exc).__name__}: {exc}"
            else:
                folder = _module_folder(path, chosen)
            tasks.extend((sid, exercise, folder) for exercise in chosen)

        from tqdm.auto import tqdm

        with ThreadPoolExecutor(max_workers=int(jobs)) as pool:
            futures = [pool.submit(_grade_one, ex, folder, limits, sources) for _, ex, folder in tasks]
            for (sid, _, _), future in tqdm(zip(tasks, futures), total=len(tasks), desc="grading", disable=not progress):
                students[sid].grades.append(future.result())
                if len(students[sid].grades) == len(chosen):  # a finished student is saved at once
                    write_student(out, students[sid])

    summary = GradeSummary(list(students.values()), chosen, out, time.monotonic() - start)
    after = _fingerprint(root, chosen)
    for path, digest in before.items():
        if after.get(path) != digest:
            summary.warnings.append(f"{path} changed while grading (a submission wrote to it?): restore it "
                                    "from git; this run used the copy read at the start")
    atomic_write_text(out / "grades.csv", class_csv(summary))
    return summary


def _test_output(score: TestScore) -> str:
    if score.passed:
        return "passed"
    parts = [f"hint: {score.hint}"]
    if score.message:
        parts.append(f"what happened: {score.message}")
    if score.detail:
        parts.append("traceback (tail):\n" + score.detail)
    if score.output:
        parts.append("your code printed (tail):\n" + score.output)
    return "\n".join(parts)


def gradescope_json(student: StudentGrade) -> dict:
    """Gradescope autograder results (https://gradescope-autograders.readthedocs.io, results.json)."""
    tests = []
    for g in student.grades:
        number = exercise_number(g.exercise)
        for i, s in enumerate(g.scores, start=1):
            tests.append({
                "name": f"{number} {g.exercise.id}: {s.name}",
                "number": f"{number}.{i}",
                "score": s.points,
                "max_score": s.max_points,
                "status": "passed" if s.passed else "failed",
                "output": _test_output(s),
                "visibility": "visible",
            })
    notes = [f"{g.exercise.id}: {g.reason}" for g in student.grades if g.reason]
    if student.problem:
        notes.insert(0, student.problem)
    total = sum(s.max_points for g in student.grades for s in g.scores)
    return {
        "score": student.points,
        "output": f"coursekit autograder: {student.points:g} / {total:g} points" + "".join(f"\n- {n}" for n in notes),
        "visibility": "visible",
        "stdout_visibility": "hidden",
        "tests": tests,
    }


def feedback_markdown(student: StudentGrade) -> str:
    """A readable per-student report."""
    total = sum(s.max_points for g in student.grades for s in g.scores)
    lines = [f"# Feedback for {student.student}", "", f"Total: **{student.points:g} / {total:g}**", ""]
    if student.problem:
        lines += [f"Problem with the submission: {student.problem}", ""]
    for g in student.grades:
        e = g.exercise
        lines += [f"## Exercise {exercise_number(e)} ({e.id}): {e.title} — {g.points:g} / {e.max_points:g}", ""]
        if g.reason:
            lines += [f"**Note:** {g.reason}", ""]
        lines += ["| test | points | result |", "|---|---|---|"]
        lines += [f"| `{s.name}` | {s.points:g} / {s.max_points:g} | {'pass' if s.passed else 'FAIL'} |" for s in g.scores]
        lines.append("")
        for s in g.scores:
            if s.passed:
                continue
            lines += [f"### `{s.name}`", "", f"- hint: {s.hint}"]
            if s.message:
                lines.append(f"- what happened: `{s.message.replace('`', chr(39))}`")
            if s.detail:
                lines += ["", "```", s.detail.replace("```", "'''"), "```"]
            if s.output:
                lines += ["", "Your code printed (tail):", "", "```", s.output.replace("```", "'''"), "```"]
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def class_csv(summary: GradeSummary) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    ids = [e.id for e in summary.exercises]
    writer.writerow(["student", *ids, "total", "max", "notes"])
    max_total = sum(e.max_points for e in summary.exercises)
    for student in sorted(summary.students, key=lambda s: s.student):
        by_id = {g.exercise.id: g for g in student.grades}
        notes = [student.problem] if student.problem else []
        notes += [f"{g.exercise.id}: {g.status}" for g in student.grades if g.status != "ok"]
        writer.writerow([student.student, *(f"{by_id[i].points:g}" for i in ids), f"{student.points:g}",
                         f"{max_total:g}", "; ".join(notes)])
    return buffer.getvalue()


def write_student(out: Path, student: StudentGrade) -> None:
    """<student>/results.json and <student>/feedback.md, each written atomically."""
    atomic_write_text(out / student.student / "results.json", json.dumps(gradescope_json(student), indent=2) + "\n")
    atomic_write_text(out / student.student / "feedback.md", feedback_markdown(student))
