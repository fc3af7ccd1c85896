"""coursekit.check / `coursekit check`: a table of test, points, pass/FAIL and hint, in seconds."""

from __future__ import annotations

import pytest

import coursekit
from coursekit.cli import main
from coursekit.grading.exercises import get_exercise, repo_root


def test_check_on_solutions_and_on_the_stub(capsys):
    exercise = get_exercise("chunk_windows")
    good = coursekit.check("chunk_windows", repo_root() / "solutions")
    out = capsys.readouterr().out
    assert good.all_passed and good.points == good.max_points == exercise.max_points
    assert "Exercise 1.1 (chunk_windows)" in out and f"score {exercise.max_points:g} / {exercise.max_points:g}" in out
    assert "FAIL" not in out and out.count(" pass") == len(exercise.tests)

    bad = coursekit.check("chunk_windows", repo_root() / "exercises")
    out = capsys.readouterr().out
    assert not bad.all_passed and bad.points == 0
    assert out.count("FAIL") == len(exercise.tests)
    for _, hint in exercise.tests.values():
        assert f"hint: {hint}" in out
    assert "NotImplementedError: Exercise 1.1" in out
    assert repr(bad) == f"CheckResult(chunk_windows: 0 / {exercise.max_points:g})"


def test_check_uses_the_environment_like_load_exercise(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("COURSEKIT_EXERCISES", "solutions")
    assert coursekit.check("chunk_windows", show=False).all_passed
    assert capsys.readouterr().out == ""
    # a student's half-right module: partial credit, and the failing tests say why
    source = (repo_root() / "solutions" / "chunk_windows.py").read_text()
    (tmp_path / "chunk_windows.py").write_text(source.replace("t - horizon + pad_after", "t - horizon"))
    partial = coursekit.check("chunk_windows", tmp_path, show=False)
    assert 0 < partial.points < partial.max_points
    assert any("Arrays are not equal" in s.message for s in partial.scores if not s.passed)


def test_cli_exit_code(capsys):
    assert main(["check", "chunk_windows", "--dir", str(repo_root() / "solutions")]) == 0
    assert main(["check", "chunk_windows", "--dir", str(repo_root() / "exercises")]) == 1
    assert main(["check", "nope"]) == 2
    assert "unknown exercise" in capsys.readouterr().err


def test_grade_cli_rejects_bad_input(tmp_path, capsys):
    assert main(["grade", str(tmp_path / "nope"), "--out", str(tmp_path / "out")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["grade", str(tmp_path), "--out", str(tmp_path / "out"), "--jobs", "0"]) == 2
    assert "argument --jobs: must be an integer in [1, 256], got '0'" in capsys.readouterr().err
    assert main(["grade", str(tmp_path), "--out", str(tmp_path / "out"), "--timeout", "-1"]) == 2
    assert "argument --timeout: must be a finite number in (0, 3600], got '-1'" in capsys.readouterr().err
    (tmp_path / "subs").mkdir()  # --out must be outside the submissions folder (coursekit.outputs)
    assert main(["grade", str(tmp_path / "subs"), "--out", str(tmp_path / "out"), "--exercise", "nope"]) == 2
    assert "unknown exercise 'nope'" in capsys.readouterr().err
    assert main(["grade", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert "is inside the input" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["subs"], "the refused runs left something behind"


def test_zip_members_are_flattened_and_size_capped(tmp_path):
    import zipfile

    from coursekit.grading.exercises import EXERCISES
    from coursekit.grading.grade import extract_zip
    from coursekit.grading.trusted import MAX_MODULE_BYTES

    archive = tmp_path / "s.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.writestr("../../outside/chunk_windows.py", "X = 1\n")  # path traversal: only the basename counts
        zf.writestr("deep/er/chunk_windows.py", "X = 2\n")  # shallower member wins, deeper ignored
        zf.writestr("notes.txt", "hello")
        zf.writestr(f"{EXERCISES[-1].id}.py", "#" * (MAX_MODULE_BYTES + 1))  # too big: not extracted
    dest = tmp_path / "dest"
    dest.mkdir()
    assert extract_zip(archive, dest, list(EXERCISES)) == {f"{EXERCISES[-1].id}.py": MAX_MODULE_BYTES + 1}
    assert sorted(p.name for p in dest.iterdir()) == ["chunk_windows.py"]
    assert (dest / "chunk_windows.py").read_text() == "X = 2\n"
    assert not (tmp_path / "outside").exists()


def test_partial_credit_hints_by_failure_kind_and_hidden_tests():
    from coursekit.grading.report import LEADS, TestOutcome, exercise_status, score_exercise

    exercise = get_exercise("chunk_windows")
    file = "test_chunk_windows.py"
    outcomes = [TestOutcome(f"{file}::{name}", "passed") for name in exercise.tests
                if name not in ("test_matches_library_on_random_datasets", "test_edge_padding", "test_window_count")]
    outcomes += [TestOutcome(f"{file}::test_matches_library_on_random_datasets[{i}]", o, "boom" if o == "failed" else "",
                             kind="value" if o == "failed" else "")
                 for i, o in enumerate(["passed", "failed", "passed", "not run"])]
    outcomes.append(TestOutcome(f"{file}::test_edge_padding", "failed", "ValueError: nope", kind="error", cause="error"))
    outcomes.append(TestOutcome(f"{file}::test_window_count", "failed", "Timeout (>1s)", kind="timeout", cause="timeout"))
    outcomes.append(TestOutcome("hidden_x.py::test_secret", "failed", "secret message", "secret traceback", kind="value"))
    scores = {s.name: s for s in score_exercise(exercise, outcomes, "", {"hidden_x.py": {"test_secret": 2.0}})}
    random = scores["test_matches_library_on_random_datasets"]
    assert random.points == exercise.tests[random.name][0] * 2 / 4 and not random.passed
    assert random.message == "2/4 cases failed; first: boom"
    assert random.hint == exercise.tests[random.name][1]  # a wrong value: the maths hint alone
    assert scores["test_edge_padding"].hint.startswith(LEADS["error"])  # raised: fix that first
    assert scores["test_edge_padding"].hint.endswith(exercise.tests["test_edge_padding"][1])
    assert scores["test_window_count"].hint.startswith(LEADS["timeout"])
    secret = scores["test_secret"]
    assert secret.hidden and secret.max_points == 2 and secret.points == 0
    assert secret.hint == secret.message == secret.detail == "", "a hidden test shows name, points and pass/fail only"
    assert exercise_status(outcomes) == "timeout"
    missing = score_exercise(exercise, [], "chunk_windows.py was not found in the submission")
    assert [s.message for s in missing] == ["chunk_windows.py was not found in the submission"] * len(exercise.tests)
    assert all(s.outcome == "not run" and s.kind == "error" and s.points == 0 for s in missing)


@pytest.mark.slow
def test_one_wrong_function_fails_only_its_own_tests(tmp_path):
    """Issue 18: the epsilon_loss tests use the REFERENCE q_sample, so a wrong q_sample does not cascade."""
    source = (repo_root() / "solutions" / "noise_loss.py").read_text()
    broken = source.replace("def q_sample(", "def q_sample(*args, **kwargs):\n    raise ValueError('broken q_sample')\n\n\ndef _unused(", 1)
    assert broken != source
    (tmp_path / "noise_loss.py").write_text(broken)
    result = coursekit.check("noise_loss", tmp_path, show=False)
    by_name = {s.name: s for s in result.scores}
    assert all(not s.passed and "broken q_sample" in s.message for n, s in by_name.items() if n.startswith("test_q_sample")), \
        [(n, s.message) for n, s in by_name.items()]
    assert all(s.passed for n, s in by_name.items() if n.startswith("test_epsilon_loss")), \
        [(n, s.message) for n, s in by_name.items() if not s.passed]


def test_without_bwrap_grading_says_so_once(tmp_path, monkeypatch, capsys):
    import shutil

    from coursekit.grading import bubblewrap
    from coursekit.grading.grade import grade_submissions

    for name in ("ann", "ben"):
        (tmp_path / "subs" / name).mkdir(parents=True)
        shutil.copy(repo_root() / "solutions" / "chunk_windows.py", tmp_path / "subs" / name)
    monkeypatch.setenv(bubblewrap.MODE_ENV, "none")
    summary = grade_submissions(tmp_path / "subs", tmp_path / "out", ["chunk_windows"], jobs=2, progress=False)
    assert summary.mode == "none" and all(s.points == 10 for s in summary.students)
    assert capsys.readouterr().out.count(bubblewrap.NOT_ISOLATED) == 1
    monkeypatch.setenv(bubblewrap.MODE_ENV, "sometimes")
    with pytest.raises(ValueError, match="COURSEKIT_SANDBOX must be auto, bwrap or none, got 'sometimes'"):
        bubblewrap.mode()
