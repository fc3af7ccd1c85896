"""`coursekit train --resume`: a run stopped by SIGKILL continues to the same bytes as one never stopped."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # several short training processes

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    from coursekit.experts.pusht_planner import collect_dataset

    path = tmp_path_factory.mktemp("data") / "demos.npz"
    collect_dataset(2, 0, progress=False).save(path)
    return path


def cmd(data: Path, out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "coursekit.cli", "train", "--data", str(data), "--out", str(out), "--steps", "200",
            "--down-dims", "16,32", "--batch-size", "8", "--threads", "1", "--seed", "1", "--checkpoint-every",
            "0.001", "--no-progress", *extra]  # a resume state at every log point (every 50 steps)


def weights(run: Path) -> str:
    return hashlib.sha256((run / "model.safetensors").read_bytes()).hexdigest()


def steps(run: Path) -> list[int]:
    return [int(line.split(",")[0]) for line in (run / "metrics.csv").read_text().splitlines()[1:]]


@pytest.fixture(scope="module")
def finished(data, tmp_path_factory):
    """A --resume run never stopped: the reference bytes (and a finished run for the refusals)."""
    ref = tmp_path_factory.mktemp("ref") / "run"
    done = subprocess.run(cmd(data, ref, "--resume"), env=ENV, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return ref


@pytest.mark.timeout(600)
def test_killed_run_resumes_to_the_uninterrupted_bytes(data, finished, tmp_path):
    run = tmp_path / "run"
    proc = subprocess.Popen(cmd(data, run, "--resume"), env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    while not (run / "train_state.pt").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert (run / "train_state.pt").exists(), "the run ended before its first resume state: nothing was tested"
    again = subprocess.run(cmd(data, run, "--resume"), env=ENV, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert "resuming" in again.stdout and " at step " in again.stdout
    assert weights(run) == weights(finished)
    assert steps(run) == steps(finished) == [50, 100, 150, 200], "each logged step once, as in the uninterrupted run"
    for r in (run, finished):
        assert sorted(p.name for p in r.iterdir()) == ["config.json", "loss.png", "metrics.csv", "model.safetensors"]


@pytest.mark.timeout(300)
@pytest.mark.parametrize("extra, message", [
    (["--minutes", "1"], "--resume needs a step budget"),
    (["--overwrite"], "--resume continues the run at --out; --overwrite replaces it"),
    ([], "holds no resume state (train_state.pt): it is a finished run"),
])
def test_resume_refusals_touch_nothing(data, finished, extra, message):
    before = {p.name: p.read_bytes() for p in finished.iterdir()}
    done = subprocess.run(cmd(data, finished, "--resume", *extra), env=ENV, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 2 and message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert {p.name: p.read_bytes() for p in finished.iterdir()} == before
    assert sorted(p.name for p in finished.parent.iterdir()) == ["run"], "nothing written beside it"
