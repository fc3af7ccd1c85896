"""Reading a submissions folder (coursekit/grading/grade.py): ids, skipped entries, oversized modules
and the one total every report shows (issue 22, item 8)."""

from __future__ import annotations

import csv
import json
import shutil
import zipfile

import pytest

from coursekit.cli import main
from coursekit.grading.exercises import get_exercise, repo_root
from coursekit.grading.grade import discover, extract_zip, student_id
from coursekit.grading.trusted import MAX_MODULE_BYTES


@pytest.mark.parametrize("name, expected", [
    ("émile", "emile"), ("Zoë Ørsted-Straße", "Zoe_Orsted-Strasse"), ("Łukasz Æbeltoft", "Lukasz_AEbeltoft"),
    ("张伟", "u5f20u4f1f"), ("ｆｕｌｌ", "full"), ("a/b c", "a_b_c"), ("..__..", "student"), ("bob 🎓", "bob"),
])
def test_ids_keep_every_letter_in_ascii(name, expected):
    assert student_id(name, set()) == expected


def test_ids_never_collide():
    taken: set[str] = set()
    assert [student_id(n, taken) for n in ("émile", "emile", "Émile", "émile!")] == \
        ["emile", "emile_2", "Emile", "emile_3"]


def test_dot_entries_are_named_not_dropped(tmp_path):
    for name in ("alice", ".bob", "émile", ".git"):
        (tmp_path / name).mkdir()
    (tmp_path / ".carol.zip").write_bytes(b"")
    (tmp_path / ".DS_Store").write_bytes(b"")  # neither a folder nor a zip: not a submission at all
    entries, skipped = discover(tmp_path)
    assert [(sid, p.name) for sid, p in entries] == [("alice", "alice"), ("emile", "émile")]
    assert skipped == [".bob", ".carol.zip", ".git"]


def test_an_oversized_zip_member_is_reported_with_its_size(tmp_path):
    archive = tmp_path / "s.zip"
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("sub/chunk_windows.py", "#" * (3 * 2**20))
        zf.writestr("kl.py", "X = 1\n")
        zf.writestr("deeper/still/chunk_windows.py", "X = 2\n")  # the shallower member decides
    dest = tmp_path / "dest"
    dest.mkdir()
    exercises = [get_exercise("chunk_windows"), get_exercise("kl")]
    assert extract_zip(archive, dest, exercises) == {"chunk_windows.py": 3 * 2**20}
    assert sorted(p.name for p in dest.iterdir()) == ["kl.py"]


@pytest.mark.slow  # one grading run (a trusted pytest process and a worker): ~10-20 s
def test_one_grading_run_gives_every_student_a_clear_row(tmp_path, capsys):
    """émile keeps her name in `folder`, the dot folder is named in a warning, an oversized module says
    its size and the limit, and the console, grades.csv, feedback.md and results.json agree on the
    maximum when hidden tests add points."""
    solution = (repo_root() / "solutions" / "chunk_windows.py").read_bytes()
    subs = tmp_path / "subs"
    for name in ("émile", ".late"):
        (subs / name).mkdir(parents=True)
        (subs / name / "chunk_windows.py").write_bytes(solution)
    (subs / "huge").mkdir()
    (subs / "huge" / "chunk_windows.py").write_bytes(solution + b"#" * MAX_MODULE_BYTES)
    with zipfile.ZipFile(subs / "zipped.zip", "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("chunk_windows.py", solution + b"#" * (200 * 2**20))
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    (hidden / "test_extra.py").write_text('EXERCISE = "chunk_windows"\nPOINTS = {"test_extra": 1}\n\n\n'
                                          'def test_extra(student):\n    pass\n')
    out = tmp_path / "out"
    assert main(["grade", str(subs), "--out", str(out), "--exercise", "chunk_windows", "--hidden-tests", str(hidden),
                 "--timeout", "120", "--test-timeout", "30", "--no-progress"]) == 0
    console = capsys.readouterr().out
    full = get_exercise("chunk_windows").max_points + 1
    rows = {r["student"]: r for r in csv.DictReader((out / "grades.csv").open(encoding="utf-8"))}
    assert set(rows) == {"emile", "huge", "zipped"}
    assert rows["emile"]["folder"] == "émile" and float(rows["emile"]["total"]) == full
    assert {r["max"] for r in rows.values()} == {f"{full:g}"}
    assert f"{'emile':<24} {full:>6g} / {full:g}" in console
    for sid, size in (("huge", len(solution) + MAX_MODULE_BYTES), ("zipped", len(solution) + 200 * 2**20)):
        assert float(rows[sid]["total"]) == 0 and rows[sid]["notes"] == "chunk_windows: too_large", rows[sid]
        reason = f"chunk_windows.py is {size / 2**20:.1f} MiB, over the 2 MiB limit for a submitted module: not graded"
        assert reason in (out / sid / "feedback.md").read_text() and "not found" not in (out / sid / "feedback.md").read_text()
        assert f"{sid:<24} {0:>6g} / {full:g}  chunk_windows: too_large" in console
    assert "WARNING: not graded (the name starts with '.'): .late; rename a student's submission to grade it" in console
    result = json.loads((out / "emile" / "results.json").read_text())
    assert result["score"] == full and f"{full:g} / {full:g} points" in result["output"]
    assert f"Total: **{full:g} / {full:g}**" in (out / "emile" / "feedback.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == [".coursekit-grade.json", "emile", "grades.csv", "huge", "zipped"]
