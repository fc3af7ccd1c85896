"""`coursekit grade` on the hostile corpus (tests/grading_corpus/) plus solutions/ and exercises/:
the expected score and reason for every student, Gradescope JSON, feedback, nothing forged,
and the same bytes when graded again."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from coursekit.cli import main
from coursekit.grading.exercises import repo_root
from coursekit.grading.grade import grade_submissions
from coursekit.grading.sandbox import Limits
from coursekit.grading.trusted import RunResult, interpret_messages

pytestmark = pytest.mark.slow  # ~20 subprocesses, two of them endless loops: ~30-60 s on 2 busy cores
CORPUS = Path(__file__).parent / "grading_corpus"
# short limits keep the run bounded: the two endless loops cost ~1 s per test / the 20 s budget
# (the budget also covers the fresh subprocesses after each crash, slow when the machine is busy)
LIMITS = Limits(timeout_s=20, test_timeout_s=1, memory_mb=512, output_mb=8)

# student -> (points out of 10, status, text that must appear in the feedback)
EXPECTED = {
    "reference_solutions": (10, "ok", "Total: **10 / 10**"),
    "untouched_stub": (0, "ok", "NotImplementedError: Exercise 1.1"),
    "syntax_error": (0, "ok", "SyntaxError: expected ':'"),
    "import_error": (0, "ok", "ModuleNotFoundError: No module named 'a_module_that_does_not_exist'"),
    "infinite_loop": (0, "timeout", "Timeout (>1s)"),
    "hang_ignoring_timeout": (0, "timeout", "Timeout (>1s)"),
    "huge_allocation": (0, "ok", "MemoryError"),
    "os_exit": (0, "crashed", "exited with code 0 while running your code"),
    "exit_at_import": (0, "crashed", "exited with code 3 while importing your module"),
    "sys_exit": (0, "ok", "SystemExit: 0"),
    "print_flood": (10, "ok", "Total: **10 / 10**"),
    "print_forever": (0, "output", "more than the 8 MiB output limit"),
    "delete_files": (10, "ok", "Total: **10 / 10**"),
    # writes fake result lines to every file descriptor: its own reply channel breaks, nothing is forged
    "forge_results": (0, "protocol", "the worker sent a"),
    # patches the tests' module, numpy and the library in ITS process: the comparisons run elsewhere,
    # so its wrong code earns exactly what its outputs earn (right shapes and dtypes: 1 point)
    "tamper_tests": (1, "ok", "Arrays are not equal"),
    "tamper_reference": (1, "ok", "Arrays are not equal"),
    "wrong_types": (0, "ok", "expected (W, 16)"),
    # dies on short episodes only: test_short_episode_gets_one_window (1) and test_windows_stay_in_their_episode (2)
    # and the random-dataset test (1) are lost, the rest keep their points in fresh subprocesses
    "exit_on_short_episode": (6, "crashed", "exited with code 0 while running your code"),
    "off_by_padding": (4, "ok", "Arrays are not equal"),
    "missing_module": (0, "missing", "chunk_windows.py was not found"),
    "broken": (0, "missing", "could not read broken.zip"),
    "zipped": (10, "ok", "Total: **10 / 10**"),
}


def _submissions(tmp_path: Path, names=None) -> Path:
    subs = tmp_path / "submissions"
    subs.mkdir()
    for entry in sorted(CORPUS.iterdir()):
        if entry.name in ("README.md", "attacks") or (names and entry.stem not in names):
            continue
        (shutil.copytree if entry.is_dir() else shutil.copy)(entry, subs / entry.name)
    if not names:
        shutil.copytree(repo_root() / "solutions", subs / "reference_solutions")
        shutil.copytree(repo_root() / "exercises", subs / "untouched_stub")
    return subs


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("corpus")
    out = tmp / "out"
    summary = grade_submissions(_submissions(tmp), out, ["chunk_windows"], jobs=2, limits=LIMITS, progress=False)
    return summary, out


def test_every_student_gets_the_expected_row(graded):
    summary, out = graded
    rows = {r["student"]: r for r in csv.DictReader((out / "grades.csv").open())}
    assert set(rows) == set(EXPECTED)
    for student, (points, status, text) in EXPECTED.items():
        row = rows[student]
        assert float(row["chunk_windows"]) == points and float(row["total"]) == points, (student, row)
        assert row["max"] == "10"
        assert row["folder"] == next(p.name for p in (out.parent / "submissions").iterdir() if p.stem == student)
        grade = next(s for s in summary.students if s.student == student).grades[0]
        if status is not None:
            assert grade.status == status, (student, grade.status, grade.reason)
        feedback = (out / student / "feedback.md").read_text()
        assert text in feedback, f"{student}: {text!r} not in feedback:\n{feedback[:3000]}"
    assert summary.warnings == []
    # feedback never shows this machine's paths; a traceback shared by every test is shown once
    for student in EXPECTED:
        feedback = (out / student / "feedback.md").read_text()
        assert str(repo_root()) not in feedback and "/tmp/" not in feedback, (student, feedback[:2000])
    stub = (out / "untouched_stub" / "feedback.md").read_text()
    assert stub.count("NotImplementedError: Exercise 1.1") >= 7 and stub.count("the same as in `") == 6
    # bounded (loose: the machine may be busy): the budget is dominated by the endless loops
    assert summary.seconds < 300


def test_gradescope_results_json(graded):
    _, out = graded
    for student, (points, _, _) in EXPECTED.items():
        result = json.loads((out / student / "results.json").read_text())
        assert result["score"] == points
        tests = result["tests"]
        assert len(tests) == 7 and {t["status"] for t in tests} <= {"passed", "failed"}
        assert sum(t["score"] for t in tests) == pytest.approx(points)
        assert sum(t["max_score"] for t in tests) == 10
        for t in tests:
            assert t["name"].startswith("1.1 chunk_windows: test_") and t["number"].startswith("1.1.")
            assert (t["status"] == "passed") == (t["score"] == t["max_score"])
            if t["status"] == "failed":
                assert "hint: " in t["output"]


def test_nothing_forged_or_left_behind(graded):
    _, out = graded
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    expected = ["grades.csv"] + sorted(f"{s}/{f}" for s in EXPECTED for f in ("feedback.md", "results.json"))
    assert files == sorted(expected)
    assert "forge_results,10" not in (out / "grades.csv").read_text()


def test_regrading_gives_identical_files(tmp_path):
    names = ["exit_on_short_episode", "tamper_tests", "syntax_error", "zipped"]
    subs = _submissions(tmp_path, names)
    outs = [tmp_path / "first", tmp_path / "second"]
    for out in outs:
        assert main(["grade", str(subs), "--out", str(out), "--exercise", "chunk_windows", "--jobs", "2",
                     "--timeout", "30", "--test-timeout", "5", "--memory-mb", "512", "--no-progress"]) == 0
    first = {p.relative_to(outs[0]): p.read_bytes() for p in outs[0].rglob("*") if p.is_file()}
    second = {p.relative_to(outs[1]): p.read_bytes() for p in outs[1].rglob("*") if p.is_file()}
    assert first == second and len(first) == 2 + 2 * len(names)  # grades.csv, the output's record, 2 per student


def test_only_nonce_tagged_lines_count():
    nonce = "ab" * 16
    lines = [
        {"nonce": nonce, "event": "collected", "tests": ["test_x.py::test_a", "test_x.py::test_b"]},
        {"nonce": "0" * 32, "event": "result", "test": "test_x.py::test_a", "outcome": "passed"},  # forged
        {"nonce": nonce, "event": "result", "test": "test_x.py::test_a", "outcome": "failed", "message": "boom"},
        {"nonce": nonce, "event": "result", "test": "test_x.py::test_a", "outcome": "passed"},  # duplicate
        {"event": "result", "test": "test_x.py::test_b", "outcome": "passed"},  # untagged
        {"nonce": nonce, "event": "start", "test": "test_x.py::test_b"},
    ]
    data = ("\n".join(json.dumps(x) for x in lines) + "\nnot json\n").encode()
    result = RunResult()
    interpret_messages(data, nonce, 0, result)
    outcomes = {o.name: o for o in result.outcomes}
    assert outcomes["test_x.py::test_a"].outcome == "failed" and outcomes["test_x.py::test_a"].message == "boom"
    assert outcomes["test_x.py::test_b"].outcome == "failed"
    assert result.status == "crashed" and "did not finish" in outcomes["test_x.py::test_b"].message
