"""``coursekit grade``: grade a folder of submissions safely and write the class's results.

Layout of ``SUBMISSIONS_DIR``: one entry per student, either a folder (a copy of the handed-out
``exercises/``; the modules may also sit one folder down) or a ``.zip`` of it. The student id is
the folder name (or the zip's stem) SANITISED: accented letters lose their accents (``émile`` ->
``emile``, ``ß`` -> ``ss``), other non-ASCII letters and digits become their code point
(``u5f20``), every run of other characters than ASCII letters, digits, ``.``, ``_`` and ``-``
becomes one ``_``, leading/trailing ``.``/``_`` are dropped (empty: "student"), and a clash gets
``_2``, ``_3``, ... in sorted order; the ``folder`` column of grades.csv maps each id back to the
submission's own name. Entries whose name starts with ``.`` are not graded: the summary's
warnings name them. For every student one trusted test
process runs the graded tests (:func:`coursekit.grading.trusted.run_tests`), each exercise's
student code in its own sandboxed worker; the test files are read once at the start.

Written to ``--out`` (each file atomically, as soon as it is complete; contents deterministic:
no timestamps or timings)::

    grades.csv                 student, folder, points per exercise, total, max, notes
    <student>/results.json     Gradescope format: score, tests[name, number, score, max_score, status, output]
    <student>/feedback.md      readable feedback: per test points, hint and what went wrong
"""

from __future__ import annotations

import csv
import hashlib
import importlib.util
import io
import json
import os
import re
import tempfile
import time
import unicodedata
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from coursekit.atomic import atomic_write_text
from coursekit.grading import bubblewrap
from coursekit.grading.exercises import EXERCISES, Exercise, get_exercise, read_test_sources, repo_root
from coursekit.grading.report import (HiddenTests, TestOutcome, exercise_status, feedback_markdown, gradescope_json,
                                      load_hidden_tests, score_exercise)
from coursekit.grading.sandbox import Limits
from coursekit.grading.trusted import MAX_MODULE_BYTES, RunResult, run_tests

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")
# Latin letters that Unicode does not decompose into a base letter and an accent
_LETTERS = {"ß": "ss", "ẞ": "SS", "æ": "ae", "Æ": "AE", "œ": "oe", "Œ": "OE", "ø": "o", "Ø": "O", "ł": "l",
            "Ł": "L", "đ": "d", "Đ": "D", "ð": "d", "Ð": "D", "þ": "th", "Þ": "Th", "ı": "i"}


@dataclass
class ExerciseGrade:
    """One student's result on one exercise."""

    exercise: Exercise
    scores: list[TestOutcome]
    """One scored record per graded (and hidden) test."""
    status: str
    """"ok", "missing", "too_large" (the module is over MAX_MODULE_BYTES), "timeout", "memory", "crashed",
    "output", "reference", "protocol" or "error"."""
    reason: str = ""

    @property
    def points(self) -> float:
        return round(sum(s.points for s in self.scores), 6)

    @property
    def max_points(self) -> float:
        """What the exercise is worth: its registered tests plus its hidden ones."""
        return round(sum(s.max_points for s in self.scores), 6)


@dataclass
class StudentGrade:
    student: str
    folder: str = ""
    """The submission's own name (folder or zip) the sanitised id came from."""
    grades: list[ExerciseGrade] = field(default_factory=list)
    problem: str = ""
    """Why the submission itself could not be read (bad zip, ...), if so."""

    @property
    def points(self) -> float:
        return round(sum(g.points for g in self.grades), 6)

    @property
    def max_points(self) -> float:
        """The one total every report shows (console, grades.csv, feedback, results.json)."""
        return round(sum(g.max_points for g in self.grades), 6)


@dataclass
class GradeSummary:
    students: list[StudentGrade]
    exercises: list[Exercise]
    out: Path
    seconds: float
    warnings: list[str] = field(default_factory=list)
    mode: str = "bwrap"
    """"bwrap" (each worker in its own sandbox) or "none" (not isolated)."""
    tag: str = ""
    """COURSEKIT_WORKER value in every worker's environment (to find leftovers)."""


def _ascii(name: str) -> str:
    """``name`` in ASCII: accents dropped, a few Latin letters spelled out, other letters and digits
    as their code point (so no letter is lost and two names stay apart)."""
    out = []
    for char in unicodedata.normalize("NFKD", name):
        if char.isascii():
            out.append(char)
        elif unicodedata.combining(char):
            continue
        elif char in _LETTERS:
            out.append(_LETTERS[char])
        elif unicodedata.category(char)[0] in "LN":
            out.append(f"u{ord(char):04x}")
        else:
            out.append("_")
    return "".join(out)


def student_id(name: str, taken: set[str]) -> str:
    """The sanitised id of submission ``name`` (see the module docstring); adds it to ``taken``."""
    base = _SAFE.sub("_", _ascii(name)).strip("._") or "student"
    candidate, i = base, 2
    while candidate in taken:
        candidate, i = f"{base}_{i}", i + 1
    taken.add(candidate)
    return candidate


def discover(submissions: Path, out: Path | None = None) -> tuple[list[tuple[str, Path]], list[str]]:
    """((student id, folder or zip) for every submission, sorted by name; names of the entries skipped
    because they start with ".") (``out`` is skipped too)."""
    if not submissions.is_dir():
        raise FileNotFoundError(f"submissions folder {str(submissions)!r} does not exist")
    skip = out.resolve() if out is not None else None
    entries = [p for p in sorted(submissions.iterdir())
               if (p.is_dir() or p.suffix.lower() == ".zip") and p.resolve() != skip]
    hidden = [p.name for p in entries if p.name.startswith(".")]
    taken: set[str] = {"grades.csv"}  # never collide with the class CSV
    return [(student_id(p.stem if p.is_file() else p.name, taken), p) for p in entries
            if not p.name.startswith(".")], hidden


def _module_folder(root: Path, exercises: list[Exercise]) -> Path:
    """The folder holding the modules: ``root`` or, if only there, one folder down."""
    names = {f"{e.id}.py" for e in exercises}
    if any((root / n).is_file() for n in names):
        return root
    for sub in sorted(p for p in root.iterdir() if p.is_dir() and not p.is_symlink()):
        if any((sub / n).is_file() for n in names):
            return sub
    return root


def extract_zip(archive: Path, dest: Path, exercises: list[Exercise]) -> dict[str, int]:
    """Copy only ``<id>.py`` members (any folder depth, size-capped) out of ``archive`` into ``dest``.

    Returns module name -> size in bytes of the members left out for being over MAX_MODULE_BYTES.
    """
    wanted = {f"{e.id}.py" for e in exercises}
    oversized: dict[str, int] = {}
    with zipfile.ZipFile(archive) as zf:
        members = sorted(zf.infolist(), key=lambda m: (m.filename.count("/"), m.filename))
        for member in members:
            name = member.filename.rsplit("/", 1)[-1]
            if member.is_dir() or name not in wanted or (dest / name).exists() or "__MACOSX" in member.filename \
                    or name in oversized:
                continue
            if member.file_size > MAX_MODULE_BYTES:
                oversized[name] = member.file_size
                continue
            with zf.open(member) as fh:
                data = fh.read(MAX_MODULE_BYTES + 1)
            if len(data) <= MAX_MODULE_BYTES:
                (dest / name).write_bytes(data)
            else:  # the header understated the size
                oversized[name] = max(len(data), member.file_size)
    return oversized


def _too_large(folder: Path, exercise: Exercise, oversized: dict[str, int]) -> str:
    """Why the submitted module of ``exercise`` is not graded for its size ("" when it is fine)."""
    name = f"{exercise.id}.py"
    size = oversized.get(name)
    if size is None and (folder / name).is_file():
        size = (folder / name).stat().st_size
    if size is None or size <= MAX_MODULE_BYTES:
        return ""
    return (f"{name} is {size / 2**20:.1f} MiB, over the {MAX_MODULE_BYTES / 2**20:g} MiB limit for a submitted "
            "module: not graded")


@dataclass(frozen=True)
class _Setup:
    """What every submission's run shares, read once at the start."""

    exercises: list[Exercise]
    sources: dict[str, bytes]
    """The graded test files (:func:`coursekit.grading.exercises.read_test_sources`)."""
    hidden: HiddenTests
    limits: Limits
    mode: str
    tag: str


def _grade_student(setup: _Setup, folder: Path, oversized: dict[str, int]) -> list[ExerciseGrade]:
    """All exercises of one submission: one trusted test run, one sandboxed worker per exercise."""
    too_large = {e.id: _too_large(folder, e, oversized) for e in setup.exercises}
    present = [e for e in setup.exercises if (folder / f"{e.id}.py").is_file() and not too_large[e.id]]
    run = run_tests(present, folder, setup.limits, setup.sources, setup.hidden, mode=setup.mode,
                    tag=setup.tag) if present else RunResult()
    grades = []
    for exercise in setup.exercises:
        points = setup.hidden.points.get(exercise.id, {})
        if exercise not in present:
            status = "too_large" if too_large[exercise.id] else "missing"
            reason = too_large[exercise.id] or f"{exercise.id}.py was not found in the submission"
            grades.append(ExerciseGrade(exercise, score_exercise(exercise, [], reason, points), status, reason))
            continue
        mine = [o for o in run.outcomes if o.file == f"test_{exercise.id}.py" or o.file in points]
        status = run.status if run.status != "ok" and not mine else exercise_status(mine)
        reason = run.reason if status == run.status and run.status != "ok" else _reason(status, mine)
        grades.append(ExerciseGrade(exercise, score_exercise(exercise, run.outcomes, run.reason, points), status, reason))
    return grades


def _reason(status: str, outcomes: list[TestOutcome]) -> str:
    if status == "ok":
        return ""
    first = next((o for o in outcomes if o.cause == status), None)
    return first.message if first else status


def _fingerprint(root: Path, exercises: list[Exercise]) -> dict[str, str]:
    """Hashes of the files grading trusts: graded tests, conftest and the reference modules."""
    paths = [root / "tests" / "exercises" / "conftest.py"] + [root / e.test_module for e in exercises]
    for e in exercises:
        spec = importlib.util.find_spec(e.source)
        if spec is not None and spec.origin:
            paths.append(Path(spec.origin))
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "missing" for p in paths}


def _unpack(entries: list[tuple[str, Path]], unpack: Path, exercises: list[Exercise],
            students: dict[str, StudentGrade]) -> list[tuple[str, Path, dict[str, int]]]:
    """(student id, folder holding the modules, oversized zip members) per submission; a zip is
    extracted under ``unpack``, one that cannot be read is the student's ``problem``."""
    tasks = []
    for sid, path in entries:
        oversized: dict[str, int] = {}
        if path.is_file():
            folder = unpack / sid
            folder.mkdir()
            try:
                oversized = extract_zip(path, folder, exercises)
            except (zipfile.BadZipFile, OSError, ValueError, NotImplementedError) as exc:
                students[sid].problem = f"could not read {path.name}: {type(exc).__name__}: {exc}"
        else:
            folder = _module_folder(path, exercises)
        tasks.append((sid, folder, oversized))
    return tasks


def grade_submissions(submissions: str | Path, out: str | Path, exercises: list[str] | None = None,
                      jobs: int = 1, limits: Limits | None = None, progress: bool = True,
                      hidden_tests: str | Path | None = None) -> GradeSummary:
    """Grade every submission in ``submissions`` and write the results under ``out``.

    ``hidden_tests``: a folder of instructor-only tests (:func:`coursekit.grading.report.load_hidden_tests`).
    Prints one line when student code cannot be isolated here (no working bubblewrap).
    """
    if int(jobs) < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs!r}")
    start = time.monotonic()
    chosen = [get_exercise(e) for e in exercises] if exercises else list(EXERCISES)
    submissions, out = Path(submissions), Path(out)
    entries, dot_entries = discover(submissions, out)
    hidden = load_hidden_tests(hidden_tests) if hidden_tests is not None else HiddenTests()
    root = repo_root()
    setup = _Setup(chosen, read_test_sources(chosen, root), hidden, limits or Limits(), bubblewrap.mode(),
                   f"coursekit-grade-{os.getpid()}-{time.monotonic_ns()}")
    if setup.mode != "bwrap":
        print(bubblewrap.NOT_ISOLATED, flush=True)
    before = _fingerprint(root, chosen)
    students = {sid: StudentGrade(sid, path.name) for sid, path in entries}
    from tqdm.auto import tqdm  # here: it looks for a notebook, which takes time

    with tempfile.TemporaryDirectory(prefix="coursekit-submissions-") as unpack:
        tasks = _unpack(entries, Path(unpack), chosen, students)
        with ThreadPoolExecutor(max_workers=int(jobs)) as pool:
            futures = [pool.submit(_grade_student, setup, folder, oversized) for _, folder, oversized in tasks]
            for (sid, _, _), future in tqdm(zip(tasks, futures), total=len(tasks), desc="grading", disable=not progress):
                students[sid].grades = future.result()
                write_student(out, students[sid])  # a finished student is saved at once

    summary = GradeSummary(list(students.values()), chosen, out, time.monotonic() - start, mode=setup.mode, tag=setup.tag)
    if dot_entries:
        summary.warnings.append(f"not graded (the name starts with '.'): {', '.join(dot_entries)}; rename a "
                                "student's submission to grade it")
    after = _fingerprint(root, chosen)
    summary.warnings += [f"{path} changed while grading (a submission wrote to it?): restore it from git; this run "
                         "used the copy read at the start" for path, digest in before.items() if after.get(path) != digest]
    atomic_write_text(out / "grades.csv", class_csv(summary))
    return summary


def class_csv(summary: GradeSummary) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    ids = [e.id for e in summary.exercises]
    writer.writerow(["student", "folder", *ids, "total", "max", "notes"])
    for student in sorted(summary.students, key=lambda s: s.student):
        by_id = {g.exercise.id: g for g in student.grades}
        notes = [student.problem] if student.problem else []
        notes += [f"{g.exercise.id}: {g.status}" for g in student.grades if g.status != "ok"]
        writer.writerow([student.student, student.folder, *(f"{by_id[i].points:g}" if i in by_id else "0" for i in ids),
                         f"{student.points:g}", f"{student.max_points:g}", "; ".join(notes)])
    return buffer.getvalue()


def write_student(out: Path, student: StudentGrade) -> None:
    """<student>/results.json and <student>/feedback.md, each written atomically."""
    atomic_write_text(out / student.student / "results.json", json.dumps(gradescope_json(student), indent=2) + "\n")
    atomic_write_text(out / student.student / "feedback.md", feedback_markdown(student))
