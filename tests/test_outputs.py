"""coursekit.outputs and coursekit.output_lock: the folder swap (both ways), the per-output lock, the
record of temporaries, and the leftover sweep that removes only what that record proves coursekit made."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coursekit import output_lock, outputs
from coursekit.atomic import atomic_path, atomic_write_text
from coursekit.output_lock import OutputLock, lock_file_of, lock_output
from coursekit.outputs import replace_dir, staging_dir

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
HOLD = ("import sys, time; from coursekit.output_lock import lock_output; from coursekit.outputs import staging_dir\n"
        "with lock_output(sys.argv[1]) as lock, staging_dir(sys.argv[1], lock) as tmp:\n"
        "    print(tmp, flush=True); time.sleep(120)")


def _make(path: Path, text: str) -> Path:
    path.mkdir()
    (path / "f.txt").write_text(text)
    return path


def _holder(output: Path) -> tuple[subprocess.Popen, Path]:
    """A real process holding ``output``'s lock and a staging folder beside it; returns (process, folder)."""
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(output)], stdout=subprocess.PIPE, text=True, env=ENV)
    return proc, Path(proc.stdout.readline().strip())


def _stop(proc: subprocess.Popen) -> None:
    proc.kill()
    proc.wait()
    proc.stdout.close()


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two-renames"])
def test_replace_dir_swaps_old_and_new(tmp_path, monkeypatch, exchange):
    if not exchange:
        monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)  # as on macOS / without renameat2
    target = _make(tmp_path / "run", "old")
    with lock_output(target) as lock, staging_dir(target, lock) as tmp:
        (tmp / "f.txt").write_text("new")
        replace_dir(tmp, target, lock)
        assert (tmp / "f.txt").read_text() == "old"  # the old one waits in the staging dir, removed on exit
    assert (target / "f.txt").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging folder, no lock file left


def test_temporaries_are_unguessable_and_recorded_before_they_exist(tmp_path):
    out = tmp_path / "d.npz"
    with lock_output(out) as lock:
        with atomic_path(out, lock=lock) as tmp:
            record = json.loads(lock_file_of(out).read_text())
            assert record["pid"] == os.getpid() and record["temporaries"] == [tmp.name]
            assert output_lock._TEMPORARY.fullmatch(tmp.name) and len(tmp.name) == len(".d.npz.") + 32 + len(".tmp")
            assert stat.S_IMODE(tmp.stat().st_mode) == 0o666 & ~_umask()  # a plain open()'s mode, not mkstemp's 0600
            tmp.write_bytes(b"data")
        assert json.loads(lock_file_of(out).read_text())["temporaries"] == []
    assert out.read_bytes() == b"data" and sorted(os.listdir(tmp_path)) == ["d.npz"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_a_failed_write_leaves_the_old_file_and_nothing_else(tmp_path):
    out = tmp_path / "notes.json"
    out.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(out) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed in the middle")
    assert out.read_text() == "old" and sorted(os.listdir(tmp_path)) == ["notes.json"]


def test_a_live_holder_refuses_a_second_writer_at_once_naming_its_pid(tmp_path):
    out = tmp_path / "run"
    proc, held = _holder(out)
    try:
        start = time.monotonic()
        with pytest.raises(ValueError, match=rf"being written by another coursekit process \(PID {proc.pid}:"):
            OutputLock.acquire(out)
        assert time.monotonic() - start < 2.0 and held.is_dir()
        with pytest.raises(ValueError, match=f"PID {proc.pid}"):
            atomic_write_text(out, "x")  # every write of the same path goes through the same lock
    finally:
        _stop(proc)
    with lock_output(out) as lock:  # the lock died with its process (SIGKILL): no stale lock
        assert lock.swept == [held] and not held.exists()  # and its recorded staging folder is swept
    assert sorted(os.listdir(tmp_path)) == []


def test_the_sweep_removes_only_recorded_temporaries(tmp_path):
    users = {".run.backup_1.old": "IMPORTANT", ".run.k3j9x1_q.tmp": "old-style name, not recorded",
             ".run.0123456789abcdef0123456789abcdef.tmp": "coursekit's shape, but not recorded", "notes.txt": "mine"}
    for name, text in users.items():
        if name.endswith(".old"):
            _make(tmp_path / name, text)
        else:
            (tmp_path / name).write_text(text)
    mine = tmp_path / ".run.fedcba9876543210fedcba9876543210.tmp"
    _make(mine, "half a run")
    record = {"format": output_lock.FORMAT, "pid": 1, "temporaries": [mine.name, "notes.txt", "../outside",
                                                                       ".run.backup_1.old", "/etc/passwd"]}
    lock_file_of(tmp_path / "run").write_text(json.dumps(record))
    with lock_output(tmp_path / "run") as lock:
        assert lock.swept == [mine]
    assert sorted(os.listdir(tmp_path)) == sorted(users)
    assert (tmp_path / ".run.backup_1.old" / "f.txt").read_text() == "IMPORTANT"


def test_a_kill_between_the_two_renames_is_undone_by_the_next_writer(tmp_path):
    old = tmp_path / ".run.0123456789abcdef0123456789abcdef.old"
    old.mkdir()
    _make(old / "previous", "old")  # what the fallback swap leaves if killed after its first rename
    lock_file_of(tmp_path / "run").write_text(json.dumps({"format": output_lock.FORMAT, "temporaries": [old.name]}))
    with lock_output(tmp_path / "run") as lock:
        assert lock.swept == [old]
    assert (tmp_path / "run" / "f.txt").read_text() == "old" and sorted(os.listdir(tmp_path)) == ["run"]


def test_a_lock_file_coursekit_did_not_write_is_refused_and_kept(tmp_path):
    users = lock_file_of(tmp_path / "run")
    users.write_text("my notes, unluckily named\n")
    with pytest.raises(ValueError, match="was not written by coursekit"):
        OutputLock.acquire(tmp_path / "run")
    assert users.read_text() == "my notes, unluckily named\n" and sorted(os.listdir(tmp_path)) == [users.name]
    users.unlink()
    os.mkfifo(users)
    with pytest.raises(ValueError, match="is not coursekit's lock file"):
        OutputLock.acquire(tmp_path / "run")  # a FIFO there is never opened for writing, never waited on


def test_a_writer_that_locked_a_removed_lock_file_takes_the_one_there_now(tmp_path, monkeypatch):
    """The unlink/reopen race: B opens the lock file, A removes it and releases, B locks the removed inode."""
    out = tmp_path / "run"
    first = OutputLock.acquire(out)
    stale = os.open(lock_file_of(out), os.O_RDWR)  # B's open, just before A's release
    first.close()  # A: removes the file, then unlocks
    real_open, calls = os.open, []

    def open_(path, flags, mode=0o777):
        calls.append(path)
        return stale if len(calls) == 1 else real_open(path, flags, mode)

    monkeypatch.setattr(output_lock.os, "open", open_)
    lock = OutputLock.acquire(out)  # locks the stale inode first, sees the path no longer names it, retries
    monkeypatch.undo()
    try:
        assert len(calls) == 2
        assert os.fstat(lock._fd).st_ino == os.lstat(lock_file_of(out)).st_ino
        proc = subprocess.run([sys.executable, "-c", "import sys; from coursekit.output_lock import OutputLock\n"
                               "OutputLock.acquire(sys.argv[1])", str(out)], env=ENV, capture_output=True, text=True)
        assert proc.returncode != 0 and f"PID {os.getpid()}" in proc.stderr  # a third writer sees THIS holder
    finally:
        lock.close()


def test_folders_made_for_an_output_are_removed_when_nothing_was_written(tmp_path):
    with lock_output(tmp_path / "a" / "b" / "run"):
        assert (tmp_path / "a" / "b").is_dir()
    assert os.listdir(tmp_path) == []
