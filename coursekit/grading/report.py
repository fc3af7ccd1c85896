"""What a graded run becomes: one record per test outcome, points and hints, feedback, hidden tests.

- :class:`TestOutcome`: what happened to one test. The trusted run (:mod:`coursekit.grading.trusted`)
  reports one per pytest node (a parametrised test: one per case); :func:`score_exercise` folds the
  cases of each graded test function into one, with its points and hint.
- Points: a registered test scores ``points x passed cases / cases`` (partial credit). The hint of
  a failing test is chosen by WHAT failed (:func:`failure_kind`, :func:`choose_hint`): the student's
  code raised, timed out or crashed (fix that first; the maths hint comes second), or a comparison
  failed on a shape, a dtype, a type or the values (the registry's hint for that test, or its
  per-kind hint when the registry gives one).
- What a student reads: ``feedback.md`` and Gradescope's ``results.json``. For each failing test:
  the hint, what happened in one line, the traceback and printed output; a traceback shared by
  several tests is shown once. Paths of the instructor's machine never appear (the trusted run
  scrubs them).
- Hidden tests (:func:`load_hidden_tests`): instructor-only tests that count for points but show
  only name, points and pass/fail (no hint, message, traceback or output), so they stay secret;
  ``coursekit check`` (students) never runs them. A hidden test file is written like a graded one
  (tests/exercises/conftest.py's ``student`` / ``sandbox`` fixtures) and declares which exercise
  it tests and what each test is worth::

      EXERCISE = "chunk_windows"
      POINTS = {"test_long_episodes": 2, "test_many_short_episodes": 1}

      def test_long_episodes(student): ...
"""

from __future__ import annotations

import ast
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from coursekit.grading.exercises import Exercise, exercise_number, get_exercise


@dataclass
class TestOutcome:
    """What happened to one test: a pytest node of the trusted run, or (scored) a graded test function."""

    name: str
    """"test_<id>.py::test_x[case]" as the run reports it; "test_x" once scored."""
    outcome: str = "passed"
    """"passed", "failed", "skipped" or "not run"."""
    message: str = ""
    """One line: the assertion or exception, or why the test never finished."""
    detail: str = ""
    """Tail of the student's traceback (or the test's, for a failed comparison)."""
    output: str = ""
    """Tail of what the student's code printed during the test."""
    kind: str = ""
    """What failed (see :func:`failure_kind`); "" when it passed."""
    cause: str = ""
    """Set when the worker failed rather than a comparison: the kind again (empty otherwise)."""
    points: float = 0.0
    """Points earned (scored records only)."""
    max_points: float = 0.0
    """Points the test is worth (scored records only)."""
    hint: str = ""
    """What to look at (scored records only; never for a hidden test)."""
    hidden: bool = False
    """An instructor-only test: feedback shows name, points and pass/fail only."""

    __test__ = False  # not a pytest test class, despite the name

    @property
    def passed(self) -> bool:
        return self.outcome == "passed"

    @property
    def file(self) -> str:
        """The test file's name ("test_<id>.py" or "hidden_<name>.py")."""
        return self.name.split("::")[0].rsplit("/", 1)[-1]

    @property
    def function(self) -> str:
        """The test function's name, without parameters."""
        return self.name.split("::")[-1].split("[")[0]


MAX_TEXT = 2000
"""Characters of traceback / printed output kept per test (the tail)."""


def text_tail(text: str, limit: int = MAX_TEXT) -> str:
    """The last ``limit`` characters of a traceback or printed output."""
    return text if len(text) <= limit else "...\n" + text[-limit:]


def one_line(text: str, limit: int = 300) -> str:
    """What happened, in one line: the first few non-empty lines joined (numpy's messages start with a
    bare "AssertionError:"), cut at ``limit`` characters."""
    line = " ".join(ln.strip() for ln in text.strip().splitlines() if ln.strip())
    return line if len(line) <= limit else line[:limit] + "..."


# ------------------------------------------------------------------------------------ failure kinds
WORKER_CAUSES = ("error", "timeout", "crashed", "memory", "output", "reference", "protocol")
"""Kinds that mean the worker (the student's code) failed, not a comparison."""
_KINDS = [
    ("shape", re.compile(r"shape|size of tensor|must match the size|broadcast", re.I)),
    ("dtype", re.compile(r"dtype|data type", re.I)),
    ("type", re.compile(r"expected a .*tensor|isinstance|is not a|got <class|not an? (array|tensor|ndarray)", re.I)),
    ("value", re.compile(r"not (close|equal)|mismatch|differs|Arrays are not|!=|==|assert", re.I)),
]
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


def failure_kind(exc: BaseException | None, message: str) -> str:
    """What failed: a StudentCodeError's cause ("error", "timeout", ...) or, for a failed comparison,
    "shape", "dtype", "type" or "value" (from the assertion's message)."""
    cause = getattr(exc, "cause", None)
    if cause:
        return "error" if cause == "import" else cause
    if exc is not None and not isinstance(exc, AssertionError):
        return "error"
    for kind, pattern in _KINDS:
        if pattern.search(message):
            return kind
    return "value"


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


def exercise_status(outcomes: list[TestOutcome]) -> str:
    """"ok", or the most serious worker failure among an exercise's test outcomes (see STATUS_ORDER)."""
    causes = {o.cause for o in outcomes}
    return next((c for c in STATUS_ORDER if c in causes), "ok")


# ------------------------------------------------------------------------------------ scoring
def score_exercise(exercise: Exercise, outcomes: list[TestOutcome], reason: str = "",
                   hidden: dict[str, dict[str, float]] | None = None) -> list[TestOutcome]:
    """One scored record per registered test (and per hidden test: ``hidden`` maps file -> {test: points}).

    ``outcomes``: the run's per-case records; ``reason``: why the run went wrong, shown for a test
    with no outcome at all.
    """
    specs = [(f"test_{exercise.id}.py", name, spec[0], False) for name, spec in exercise.tests.items()]
    for file, tests in sorted((hidden or {}).items()):
        specs += [(file, name, points, True) for name, points in tests.items()]
    by_test: dict[tuple[str, str], list[TestOutcome]] = {}
    for outcome in outcomes:
        by_test.setdefault((outcome.file, outcome.function), []).append(outcome)
    return [_score(exercise, name, float(max_points), by_test.get((file, name), []), reason, is_hidden)
            for file, name, max_points, is_hidden in specs]


def _score(exercise: Exercise, name: str, max_points: float, cases: list[TestOutcome], reason: str,
           hidden: bool) -> TestOutcome:
    """One graded test function from its cases."""
    failed = [o for o in cases if not o.passed]
    first = failed[0] if failed else None
    passed = sum(o.passed for o in cases)
    scored = TestOutcome(name, "passed" if cases and not failed else ("failed" if cases else "not run"),
                         points=round(max_points * passed / len(cases), 6) if cases else 0.0,
                         max_points=max_points, hidden=hidden,
                         kind=first.kind if first else ("error" if not cases else ""))
    if not cases:
        scored.message = reason or "the test was not found in the test run"
    elif first is not None:
        label = f"{len(failed)}/{len(cases)} cases failed; first: " if len(cases) > 1 else ""
        scored.message = label + (first.message or first.outcome)
        scored.detail, scored.output = first.detail, first.output
    if hidden:
        scored.message = scored.detail = scored.output = ""
    elif scored.passed:
        scored.hint = exercise.tests[name][1]
    else:
        scored.hint = choose_hint(exercise, name, scored.kind, scored.message)
    return scored


# ------------------------------------------------------------------------------------ hidden tests
@dataclass
class HiddenTests:
    """Instructor-only test files, read once at the start of a grading run."""

    sources: dict[str, bytes] = field(default_factory=dict)
    """File name (prefixed ``hidden_`` so it never collides with a graded test file) -> its bytes."""
    points: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    """Exercise id -> {file name -> {test name -> points}}."""

    def files_for(self, exercise_ids) -> list[str]:
        """Names of the hidden test files that test one of ``exercise_ids``, sorted."""
        return sorted(name for e in exercise_ids for name in self.points.get(e, {}))


def load_hidden_tests(folder: str | Path) -> HiddenTests:
    """Every ``*.py`` in ``folder`` (conftest.py aside), checked: ValueError naming the file for a
    file that is not UTF-8 Python, names no registered exercise, or gives a test points that are
    not a finite number > 0; for an empty folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"hidden tests folder {str(folder)!r} does not exist")
    files = [p for p in sorted(folder.glob("*.py")) if p.name != "conftest.py"]
    if not files:
        raise ValueError(f"hidden tests folder {str(folder)!r} holds no test files (*.py other than conftest.py): "
                         "give a folder of hidden tests or leave out --hidden-tests")
    hidden = HiddenTests()
    for path in files:
        data = path.read_bytes()
        exercise, table = _hidden_file(data, path)
        name = path.name if path.name.startswith("hidden_") else f"hidden_{path.name}"
        hidden.sources[name] = data
        hidden.points.setdefault(exercise, {})[name] = table
    return hidden


def _hidden_file(data: bytes, path: Path) -> tuple[str, dict[str, float]]:
    """(exercise id, {test: points}) of one hidden test file."""
    tree = _parse(data, path)
    try:
        exercise = get_exercise(str(_constant(tree, "EXERCISE", path)))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}" if str(path) not in str(exc) else str(exc)) from None
    table = _constant(tree, "POINTS", path)
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")}
    if not isinstance(table, dict) or not table:
        raise ValueError(f"{path}: POINTS must map test names to points, got {table!r}")
    for test, value in table.items():
        if test not in functions:
            raise ValueError(f"{path}: POINTS names {test!r}, which is not a test function in the file")
        # a bool is not a number of points (True would count as 1); inf would reach grades.csv
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ValueError(f"{path}: points of {test!r} must be a finite number > 0, got {value!r}")
    return exercise.id, {t: float(v) for t, v in table.items()}


def _parse(data: bytes, path: Path) -> ast.Module:
    """The file's syntax tree; ValueError naming the file for bytes that are not UTF-8 or not Python."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}): "
                         "save the hidden test file as UTF-8") from None
    try:
        return ast.parse(text, filename=str(path))
    except SyntaxError as exc:
        raise ValueError(f"{path}: line {exc.lineno}: {exc.msg}") from None


def _constant(tree: ast.Module, name: str, path: Path):
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            try:
                return ast.literal_eval(node.value)
            except ValueError:
                raise ValueError(f"{path}: {name} must be a literal, got {ast.unparse(node.value)!r}") from None
    raise ValueError(f"{path}: a hidden test file must set {name} (see coursekit.grading.report)")


# ------------------------------------------------------------------------------------ feedback
def _shared(scores: list[TestOutcome]) -> dict[int, str]:
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


def _test_output(score: TestOutcome, same_as: str = "") -> str:
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
    """Gradescope autograder results (https://gradescope-autograders.readthedocs.io, results.json) of
    one :class:`coursekit.grading.grade.StudentGrade`."""
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
    """A readable per-student report (``feedback.md``) of one :class:`coursekit.grading.grade.StudentGrade`."""
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
        lines += [line for i, s in enumerate(g.scores) if not (s.passed or s.hidden)
                  for line in _failure_section(s, shared.get(i, ""))]
    return "\n".join(lines).rstrip() + "\n"


def _failure_section(s: TestOutcome, same_as: str) -> list[str]:
    """feedback.md's section on one failing (visible) test."""
    lines = [f"### `{s.name}`", "", f"- hint: {s.hint}"]
    if s.message:
        lines.append(f"- what happened: `{s.message.replace('`', chr(39))}`")
    if s.detail and same_as:
        lines.append(f"- traceback: the same as in `{same_as}` above")
    elif s.detail:
        lines += ["", "```", s.detail.replace("```", "'''"), "```"]
    if s.output:
        lines += ["", "Your code printed (tail):", "", "```", s.output.replace("```", "'''"), "```"]
    lines.append("")
    return lines
