"""The output policy from the command line: no command writes onto, into or through a user's file, or hangs.

Each refusal runs ``coursekit ...`` in an area that already holds a user's files (grades, a student's
submission, links of every kind, a FIFO, a look-alike evaluation summary) and asserts: exit status 2,
exactly one line on stderr naming the problem, every pre-existing entry byte-identical (links and
FIFOs included), nothing added (no lock file, no temporary, no folder), no process left. The positive
runs show the user's hidden look-alikes of coursekit's temporaries survive real writes, and the
concurrency tests race real ``coursekit train`` processes on one output.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
from test_bad_input_cli import originals  # noqa: F401  (module fixture: a real dataset and checkpoint)

from coursekit.cli import main
from coursekit.grading.exercises import repo_root

pytestmark = [pytest.mark.usefixtures("one_torch_thread"), pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
SOLUTION = repo_root() / "solutions" / "chunk_windows.py"


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "coursekit", *args]


@pytest.fixture
def area(tmp_path, originals):  # noqa: F811
    """A user's folder: data, a checkpoint, submissions, grades, links of every kind, a FIFO, a socket."""
    shutil.copy(originals / "demos.npz", tmp_path / "demos.npz")
    shutil.copytree(originals / "ckpt", tmp_path / "ckpt")
    (tmp_path / "notes.txt").write_text("my notes\n")
    for folder, files in {"subs/alice": ["chunk_windows.py", "results.json"], "ext/bob": ["chunk_windows.py"],
                          "user/alice": ["results.json", "feedback.md"], "hidden": ["test_more.py"],
                          "mixed": ["metrics.csv", "notes.txt"], "tour": ["demo_pusht.png"],
                          "tree/exercises": ["README.md"]}.items():
        (tmp_path / folder).mkdir(parents=True)
        for name in files:
            (tmp_path / folder / name).write_text(f"{folder}/{name}: the user's\n")
    shutil.copy(SOLUTION, tmp_path / "subs" / "alice" / "chunk_windows.py")
    (tmp_path / "mixed" / "metrics.csv").write_text("step,loss,lr,samples_per_s,wall_s\n1,0.5,0.001,10,1\n")
    (tmp_path / "user" / "grades.csv").write_text("student,total\nalice,10\n")
    (tmp_path / "old_eval.json").write_text(json.dumps({"checkpoint": "ckpt", "episodes": 3, "mine": True}))
    (tmp_path / ".locked.npz.coursekit-lock").write_text("a user's file that happens to have a lock's name\n")
    (tmp_path / "subs" / "bob").symlink_to(tmp_path / "ext" / "bob")
    (tmp_path / "userlink").symlink_to(tmp_path / "user")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    (tmp_path / "dangling.zip").symlink_to(tmp_path / "missing.zip")
    (tmp_path / "loop").symlink_to("loop")
    os.mkfifo(tmp_path / "pipe")
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(tmp_path / "sock"))
    yield tmp_path
    server.close()


def snapshot(root: Path) -> dict[str, object]:
    """Every entry under ``root`` (links never followed): file hashes, link targets, the kind of the rest."""
    state = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder) / name
            st = os.lstat(path)
            if stat.S_ISREG(st.st_mode):
                state[str(path.relative_to(root))] = hashlib.sha256(path.read_bytes()).hexdigest()
            elif stat.S_ISLNK(st.st_mode):
                state[str(path.relative_to(root))] = f"link -> {os.readlink(path)}"
            else:
                state[str(path.relative_to(root))] = stat.S_IFMT(st.st_mode)
    return state


# (command line: {A} is the area and '' an empty argument; the text the one error line must contain)
REFUSED = [
    # 1. grade --out: a user's grades, links, the submissions and what is in or around them, a file, '', '.'
    ("grade {A}/subs --out {A}/user", "--out '{A}/user' exists and is not a coursekit grade output (it has no "
                                      "readable .coursekit-grade.json"),
    ("grade {A}/subs --out {A}/user --overwrite", "exists and is not a coursekit grade output"),
    ("grade {A}/subs --out {A}/userlink", "--out '{A}/userlink' is a symbolic link (to '{A}/user'); coursekit never "
                                          "writes through links"),
    ("grade {A}/subs --out {A}/subs", "--out '{A}/subs' is the input '{A}/subs'"),
    ("grade {A}/subs --out {A}/subs/alice", "--out '{A}/subs/alice' is inside the input '{A}/subs'"),
    ("grade {A}/subs --out {A}/subs/graded", "is inside the input '{A}/subs'"),
    ("grade {A}/subs --out {A}/ext/bob", "--out '{A}/ext/bob' is the input '{A}/ext/bob'"),
    ("grade {A}/subs --out {A}/ext --overwrite", "--out '{A}/ext' contains the input '{A}/ext/bob'"),
    ("grade {A}/subs --out {A}/hidden/graded --hidden-tests {A}/hidden", "is inside the input '{A}/hidden'"),
    ("grade {A}/subs --out {A}/user/grades.csv", "--out '{A}/user/grades.csv' exists and is a file, not a coursekit "
                                                 "grade output"),
    ("grade {A}/subs --out ''", "argument --out: must name a file or folder to write, got ''"),
    ("grade {A}/subs --out .", "--out '.' is the current folder"),
    ("grade {A}/subs --out {A}/pipe", "--out '{A}/pipe' is a FIFO (named pipe), not a regular folder"),
    ("grade {A}/subs --out {A}/loop", "--out '{A}/loop' is a symbolic link (to 'loop', a loop)"),
    ("grade {A}/subs --out {A}/loop/graded", "--out '{A}/loop/graded': '{A}/loop' is a symbolic-link loop"),
    # 3. the autograder zip: a dangling link, an existing file, a FIFO
    ("grade --gradescope-autograder {A}/dangling.zip", "--gradescope-autograder '{A}/dangling.zip' is a symbolic link "
                                                       "(to '{A}/missing.zip', which does not exist)"),
    ("grade --gradescope-autograder {A}/notes.txt", "--gradescope-autograder '{A}/notes.txt' already exists: choose a "
                                                    "new name"),
    ("grade --gradescope-autograder {A}/pipe", "is a FIFO (named pipe), not a regular file"),
    # 3. eval --json: a look-alike summary; 5. FIFOs and sockets never opened
    ("eval {A}/ckpt --episodes 1 --json {A}/old_eval.json", "--json '{A}/old_eval.json' exists and is not a coursekit "
                                                            "evaluation summary (it has no \"format\": "
                                                            "\"coursekit-eval-summary\" entry)"),
    ("eval {A}/ckpt --episodes 1 --json {A}/pipe", "--json '{A}/pipe' is a FIFO (named pipe), not a regular file"),
    ("eval {A}/ckpt --episodes 1 --json {A}/sock", "--json '{A}/sock' is a socket, not a regular file"),
    ("eval {A}/ckpt --episodes 1 --json {A}/dangling", "--json '{A}/dangling' is a symbolic link (to '{A}/nowhere', "
                                                       "which does not exist)"),
    ("eval {A}/ckpt --episodes 1 --json ''", "argument --json: must name a file or folder to write, got ''"),
    ("eval {A}/ckpt --episodes 1 --record {A}/loop", "--record '{A}/loop' is a symbolic link (to 'loop', a loop)"),
    ("eval {A}/ckpt --episodes 1 --record {A}/user", "--record '{A}/user' already exists and holds 'alice'"),
    ("collect pusht --episodes 2 --out {A}/pipe", "--out '{A}/pipe' is a FIFO (named pipe), not a regular file"),
    ("collect pusht --episodes 2 --out {A}/dangling", "--out '{A}/dangling' is a symbolic link"),
    ("collect pusht --episodes 2 --out {A}/loop/d.npz", "'{A}/loop' is a symbolic-link loop"),
    ("collect pusht --episodes 2 --out {A}/locked.npz", "'{A}/.locked.npz.coursekit-lock' exists and was not written "
                                                        "by coursekit"),
    # 4. train: the current folder and '' before the data is read (it does not even exist here); links, FIFOs
    ("train --data {A}/missing.npz --steps 2 --out .", "--out '.' is the current folder"),
    ("train --data {A}/missing.npz --steps 2 --out {A}", "--out '{A}' is the current folder"),
    ("train --data {A}/missing.npz --steps 2 --out ''", "argument --out: must name a file or folder to write, got ''"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/userlink --overwrite", "is a symbolic link (to '{A}/user')"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/pipe", "is a FIFO (named pipe), not a regular folder"),
    # 10. the refused --overwrite folder names the foreign file
    ("train --data {A}/demos.npz --steps 2 --out {A}/mixed --overwrite", "--out '{A}/mixed' exists and is not a "
                                                                         "coursekit run folder (it holds 'notes.txt', "
                                                                         "which a run never writes)"),
    ("demo --episodes 1 --out {A}/tour", "--out '{A}/tour/demo_pusht.png' exists and is not a coursekit demo figure"),
    ("demo --episodes 1 --out .", "--out '.' is the current folder"),
    ("exercises build --root {A}/tree", "--root: the folder '{A}/tree/exercises' exists and is not a folder of "
                                        "generated exercises (its 'README.md' was not generated by `coursekit "
                                        "exercises build`)"),
]


@pytest.mark.parametrize("line,expected", REFUSED, ids=[c[0].replace("{A}", "A")[:70] for c in REFUSED])
def test_refused_before_any_work_touching_nothing(area, monkeypatch, capsys, line, expected):
    monkeypatch.chdir(area)
    argv = ["" if a == "''" else a.replace("{A}", str(area)) for a in line.split()]
    before, children = snapshot(area), {p.pid for p in psutil.Process().children(recursive=True)}
    start = time.monotonic()
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith(f"coursekit {argv[0]}: error: ") and "Traceback" not in err, err
    assert expected.replace("{A}", str(area)) in err, err
    assert time.monotonic() - start < 20, "refused only after some work"
    assert snapshot(area) == before, "a pre-existing entry changed, or something was written"
    assert {p.pid for p in psutil.Process().children(recursive=True)} <= children, "a process was left running"


@pytest.mark.parametrize("command", [["eval", "{A}/ckpt", "--episodes", "1", "--json", "{A}/pipe"],
                                     ["collect", "pusht", "--episodes", "2", "--out", "{A}/pipe"]],
                         ids=["eval --json FIFO", "collect --out FIFO"])
def test_a_fifo_never_blocks(area, command):
    """A real process, no reader on the FIFO: it must answer in one line at once, not wait for one."""
    before = snapshot(area)
    proc = subprocess.run(_cli(*[a.replace("{A}", str(area)) for a in command]), env=ENV, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "is a FIFO (named pipe)" in proc.stderr
    assert snapshot(area) == before


@pytest.mark.parametrize("command", [["train", "--data", "{A}/missing.npz", "--steps", "2", "--out", "{A}/ro/run"],
                                     ["collect", "pusht", "--out", "{A}/ro/d.npz"],
                                     ["eval", "{A}/ckpt", "--json", "{A}/ro/eval.json"],
                                     ["grade", "{A}/subs", "--out", "{A}/ro/graded"]],
                         ids=["train", "collect", "eval", "grade"])
def test_an_unwritable_folder_is_refused_before_any_work(area, command):
    ro = area / "ro"
    ro.mkdir()
    cmd = _cli(*[a.replace("{A}", str(area)) for a in command])
    if os.geteuid() == 0:  # access() lets root write anywhere a mount allows: make it a read-only mount
        if shutil.which("bwrap") is None:
            pytest.skip("as root this needs bubblewrap, to mount the folder read-only")
        cmd = ["bwrap", "--dev-bind", "/", "/", "--ro-bind", str(ro), str(ro), *cmd]
    else:
        ro.chmod(0o555)
    before = snapshot(area)
    proc = subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=120)
    ro.chmod(0o755)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert f": the folder '{ro}' is not writable" in proc.stderr  # train: before its (missing) data is read
    assert snapshot(area) == before


# -- 2. the user's hidden look-alikes of coursekit's temporaries survive real writes ------------------
@pytest.mark.slow
def test_a_users_backup_beside_the_output_survives_train_and_collect(area):
    runs, lo = area / "runs", area / "lo"
    for folder, name in ((runs, ".r.backup_1.old"), (lo, ".demos.npz.20241201.old")):
        (folder / name).mkdir(parents=True)
        (folder / name / "IMPORTANT.txt").write_text("my backup\n")
    (lo / ".demos.npz.k3j9x1_q.tmp").write_text("an old-style name: not recorded, so not coursekit's to remove\n")
    before = snapshot(area)
    train = _cli("train", "--data", str(area / "demos.npz"), "--out", str(runs / "r"), "--steps", "2",
                 "--down-dims", "16,32", "--batch-size", "4", "--threads", "1", "--no-progress")
    collect = _cli("collect", "pusht", "--episodes", "1", "--out", str(lo / "demos.npz"), "--no-progress")
    for cmd in (train, train + ["--overwrite"], collect, collect + ["--overwrite"]):
        proc = subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=240)
        assert proc.returncode == 0, proc.stderr
    after = snapshot(area)
    assert {k: v for k, v in after.items() if k in before} == before
    assert sorted(os.listdir(runs)) == [".r.backup_1.old", "r"]
    assert sorted(os.listdir(lo)) == [".demos.npz.20241201.old", ".demos.npz.k3j9x1_q.tmp", "demos.npz"]


def test_the_autograder_zip_never_touches_a_users_partial_file(area):
    (area / ".new.zip.partial").write_text("mine\n")
    before = snapshot(area)
    assert main(["grade", "--gradescope-autograder", str(area / "new.zip"), "--exercise", "chunk_windows"]) == 0
    after = snapshot(area)
    assert {k: v for k, v in after.items() if k in before} == before and set(after) - set(before) == {"new.zip"}


# -- 1. grade --out: a real earlier output is replaced only with --overwrite, and only if unchanged ---------
@pytest.mark.slow
def test_grade_replaces_only_its_own_unchanged_output(area, capsys):
    graded = area / "graded"
    args = ["grade", str(area / "subs"), "--exercise", "chunk_windows", "--out", str(graded), "--no-progress",
            "--timeout", "60", "--test-timeout", "20"]
    assert main(args) == 0
    assert json.loads((graded / "alice" / "results.json").read_text())["score"] > 0
    assert (area / "subs" / "alice" / "results.json").read_text() == "subs/alice/results.json: the user's\n"
    capsys.readouterr()
    assert main(args) == 2 and "already holds a coursekit grade output; pass --overwrite" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0
    assert not [p for p in os.listdir(area) if p.startswith(".graded.")], "a lock or staging folder was left"
    with open(graded / "grades.csv", "a") as fh:
        fh.write("# my note on the grades\n")  # edited since grading: now the user's
    before = snapshot(area)
    capsys.readouterr()
    assert main(args + ["--overwrite"]) == 2
    assert "(its 'grades.csv' changed since coursekit wrote it)" in capsys.readouterr().err
    assert snapshot(area) == before
    (graded / "grades.csv").unlink()
    (graded / "alice" / "mine.txt").write_text("a note\n")
    before = snapshot(area)
    assert main(args + ["--overwrite"]) == 2
    assert "(it holds 'alice/mine.txt', which coursekit did not write)" in capsys.readouterr().err
    assert snapshot(area) == before


# -- 4. two writers of one output: the second refuses at once, naming the first ----------------------------
def _train(area: Path, out: Path, *extra: str, data: str = "demos.npz") -> list[str]:
    return _cli("train", "--data", str(area / data), "--out", str(out), "--down-dims", "16,32", "--batch-size", "4",
                "--threads", "1", "--checkpoint-every", "0.05", "--no-progress", *extra)


@pytest.mark.slow
@pytest.mark.parametrize("overwrite", [False, True], ids=["new --out", "--overwrite"])
def test_a_second_train_on_the_same_out_refuses_at_once_naming_the_first(area, overwrite):
    out = area / "run"
    if overwrite:
        assert subprocess.run(_train(area, out, "--steps", "2"), env=ENV, timeout=240).returncode == 0
    extra = ["--overwrite"] if overwrite else []
    # 12 s of training: the second (no data loaded, no torch imported) refuses within a second or two
    first = subprocess.Popen(_train(area, out, "--steps", "100000", "--minutes", "0.2", *extra), env=ENV,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first.stdout.readline()  # its first line comes after the data is loaded: it holds the lock by then
        # the second names data that does not exist: a refusal about the lock proves it came before the data
        second = subprocess.run(_train(area, out, "--steps", "2", *extra, data="missing.npz"), env=ENV,
                                capture_output=True, text=True, timeout=120)
        assert first.poll() is None, "the second waited for the first instead of refusing at once"
        assert second.returncode == 2 and second.stderr.count("\n") == 1, second.stderr
        assert f"--out '{out}' is being written by another coursekit process (PID {first.pid}: coursekit train" \
            in second.stderr
        assert first.wait(timeout=240) == 0, first.stderr.read()
    finally:
        first.kill()
        first.wait()
        first.stdout.close()
        first.stderr.close()
    assert sorted(os.listdir(out)) == ["config.json", "loss.png", "metrics.csv", "model.safetensors"]
    assert not [p for p in os.listdir(area) if p.startswith(".run.")], "a lock or temporary was left beside the run"


@pytest.mark.slow
def test_two_trains_started_together_never_both_train(area):
    out = area / "run"
    procs = [subprocess.Popen(_train(area, out, "--steps", "30"), env=ENV, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.pid, *p.communicate(timeout=240), p.returncode) for p in procs]
    assert sorted(r[3] for r in results) == [0, 2], f"both trained into one --out, or neither: {results}"
    winner, loser = sorted(results, key=lambda r: r[3])
    # refused while the winner held the lock (naming it), or after it finished (its run is there now)
    assert f"(PID {winner[0]}: coursekit train" in loser[2] or "already holds a coursekit run folder" in loser[2]
    assert loser[2].count("\n") == 1, loser[2]
