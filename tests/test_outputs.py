"""coursekit.outputs: the directory swap (both ways), leftover cleaning, and what it never touches."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coursekit import outputs
from coursekit.outputs import clean_leftovers, replace_dir, staging_dir


def _make(path: Path, text: str) -> Path:
    path.mkdir()
    (path / "f.txt").write_text(text)
    return path


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two-renames"])
def test_replace_dir_swaps_old_and_new(tmp_path, monkeypatch, exchange):
    if not exchange:
        monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)  # as on macOS / without renameat2
    target = _make(tmp_path / "run", "old")
    with staging_dir(target) as tmp:
        (tmp / "f.txt").write_text("new")
        replace_dir(tmp, target)
        assert (tmp / "f.txt").read_text() == "old"  # the old one waits in the staging dir, removed on exit
    assert (target / "f.txt").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_kill_between_the_two_renames_is_undone_by_the_next_run(tmp_path):
    old = tmp_path / ".run.abcd1234.old"
    old.mkdir()
    _make(old / "previous", "old")  # what the fallback swap leaves if killed after its first rename
    assert clean_leftovers(tmp_path / "run") == [old]
    assert (tmp_path / "run" / "f.txt").read_text() == "old" and sorted(os.listdir(tmp_path)) == ["run"]


def test_only_coursekits_own_temporaries_are_removed(tmp_path):
    mine = [tmp_path / ".d.npz.0123456789abcdef0123456789abcdef.tmp", tmp_path / ".run.k3j9x1_q.tmp",
            tmp_path / "..run.k3j9x1_q.tmp.a1b2c3d4.tmp"]
    mine[0].write_bytes(b"half a file")
    mine[1].mkdir()
    mine[2].mkdir()
    users = [tmp_path / ".run.backup.old", tmp_path / ".d.npz.notes.tmp", tmp_path / "run.k3j9x1_q.tmp", tmp_path / "run"]
    for p in users:
        p.write_text("mine")
    assert sorted(clean_leftovers(tmp_path / "run") + clean_leftovers(tmp_path / "d.npz")) == sorted(mine)
    assert sorted(tmp_path.iterdir()) == sorted(users)


def test_a_staging_folder_a_live_process_holds_is_left_alone(tmp_path):
    code = ("import sys, time; from coursekit.outputs import staging_dir\n"
            "with staging_dir(sys.argv[1]) as tmp:\n    print(tmp, flush=True); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "run")], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)})
    try:
        held = Path(proc.stdout.readline().strip())
        assert clean_leftovers(tmp_path / "run") == [] and held.is_dir()
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    deadline = time.monotonic() + 5
    while not clean_leftovers(tmp_path / "run") and time.monotonic() < deadline:  # its lock died with it
        time.sleep(0.05)
    assert not held.exists()
