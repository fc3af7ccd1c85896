"""Hidden tests (coursekit/grading/report.py): a bad hidden test folder is refused with ONE line naming
the file, the test and the bad value, before any grading, and nothing is written (issue 22, items 8, 10)."""

from __future__ import annotations

import shutil
import zipfile

import pytest

from coursekit.cli import main
from coursekit.grading.exercises import repo_root
from coursekit.grading.report import HiddenTests, load_hidden_tests

GOOD = '''
EXERCISE = "chunk_windows"
POINTS = {"test_one": 2, "test_two": 0.5}


def test_one(student):
    pass


def test_two(student):
    pass
'''


def _folder(tmp_path, text: str | bytes, name: str = "test_more.py"):
    folder = tmp_path / "hidden"
    folder.mkdir()
    (folder / name).write_bytes(text if isinstance(text, bytes) else text.encode())
    return folder


def _grade_refuses(tmp_path, capsys, hidden, *expected: str) -> None:
    """`coursekit grade` and `--gradescope-autograder` both exit 2 with one line holding ``expected``,
    and write nothing."""
    subs = tmp_path / "subs"
    (subs / "alice").mkdir(parents=True)
    shutil.copy(repo_root() / "solutions" / "chunk_windows.py", subs / "alice")
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    for argv in (["grade", str(subs), "--out", str(tmp_path / "out"), "--hidden-tests", str(hidden), "--no-progress"],
                 ["grade", "--gradescope-autograder", str(tmp_path / "ag.zip"), "--hidden-tests", str(hidden)]):
        assert main(argv) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
        assert all(text in lines[0] for text in expected), (expected, lines[0])
        assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before, "something was written"


def test_a_good_folder_loads(tmp_path):
    hidden = load_hidden_tests(_folder(tmp_path, GOOD))
    assert hidden == HiddenTests({"hidden_test_more.py": GOOD.encode()},
                                 {"chunk_windows": {"hidden_test_more.py": {"test_one": 2.0, "test_two": 0.5}}})
    assert hidden.files_for(["chunk_windows", "kl"]) == ["hidden_test_more.py"] and hidden.files_for(["kl"]) == []


@pytest.mark.parametrize("value", ["1e999", "-1e999", "True", "False", "0", "-2", "'3'", "None"])
def test_points_must_be_a_finite_positive_number(tmp_path, capsys, value):
    """1e999 used to write `inf` into grades.csv and `Infinity` (invalid JSON) into results.json;
    True used to count as 1 point."""
    hidden = _folder(tmp_path, GOOD.replace('"test_two": 0.5', f'"test_two": {value}'))
    shown = {"1e999": "inf", "-1e999": "-inf"}.get(value, value)
    _grade_refuses(tmp_path, capsys, hidden, "test_more.py", "points of 'test_two' must be a finite number > 0",
                   f"got {shown}")


def test_an_empty_folder_is_refused(tmp_path, capsys):
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "conftest.py").write_text("")  # a conftest alone is not a test
    (hidden / "notes.txt").write_text("ideas for tests")
    _grade_refuses(tmp_path, capsys, hidden, str(hidden), "holds no test files")


def test_a_latin1_file_names_the_file_and_the_encoding(tmp_path, capsys):
    hidden = _folder(tmp_path, GOOD.replace("EXERCISE", "# écrit par le prof\nEXERCISE").encode("latin-1"))
    _grade_refuses(tmp_path, capsys, hidden, "test_more.py", "not UTF-8 text (byte 0xe9", "save the hidden test file as UTF-8")


def test_a_syntax_error_names_the_file_and_line(tmp_path, capsys):
    text = GOOD + "\ndef test_three(:\n"
    line = text.splitlines().index("def test_three(:") + 1
    _grade_refuses(tmp_path, capsys, _folder(tmp_path, text), f"test_more.py: line {line}: invalid syntax")


def test_an_unknown_exercise_names_the_file(tmp_path, capsys):
    hidden = _folder(tmp_path, GOOD.replace('"chunk_windows"', '"chunk_window"'))
    _grade_refuses(tmp_path, capsys, hidden, "test_more.py", "unknown exercise 'chunk_window'")


def test_the_autograder_zip_carries_the_hidden_tests(tmp_path):
    assert main(["grade", "--gradescope-autograder", str(tmp_path / "ag.zip"), "--exercise", "chunk_windows",
                 "--hidden-tests", str(_folder(tmp_path, GOOD))]) == 0
    assert zipfile.ZipFile(tmp_path / "ag.zip").read("hidden/hidden_test_more.py") == GOOD.encode()
