"""The grading child process's plumbing: its environment, its pipe, its memory, its end.

Helpers of :mod:`coursekit.grading.runner` (the parent side of a grading run).
"""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

MAX_PIPE_BYTES = 8 * 1024 * 1024
"""The parent stops storing result messages beyond this many bytes."""


def _kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL the child's whole session (children it forked included)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        proc.kill()
    except ProcessLookupError:
        pass
    proc.wait()


def _tree_rss_mb(pid: int) -> float:
    try:
        import psutil

        proc = psutil.Process(pid)
        procs = [proc, *proc.children(recursive=True)]
        return sum(p.memory_info().rss for p in procs) / 2**20
    except Exception:  # noqa: BLE001 - the process may be gone between the calls
        return 0.0


def _child_env(scratch: Path, submission: Path) -> dict[str, str]:
    """A minimal environment: nothing of the grader's own environment leaks to student code."""
    home = scratch / "work"
    env = {
        "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
        "HOME": str(home),
        "TMPDIR": str(scratch / "tmp"),
        "LANG": "C.UTF-8",
        "COURSEKIT_EXERCISES": str(submission),
        "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1",
        "MPLBACKEND": "Agg",
        # one thread per run: runs go in parallel instead, and results do not depend on threading
        "OMP_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
    }
    if os.environ.get("COURSEKIT_FAST"):
        env["COURSEKIT_FAST"] = os.environ["COURSEKIT_FAST"]
    return env


def _pump(fd: int, buffer: bytearray, received: list[int]) -> bool:
    """Read what is available from ``fd`` into ``buffer``; False at end of file."""
    try:
        chunk = os.read(fd, 65536)
    except BlockingIOError:
        return True
    if not chunk:
        return False
    if received[0] < MAX_PIPE_BYTES:
        buffer.extend(chunk[: MAX_PIPE_BYTES - received[0]])
    received[0] += len(chunk)
    return True
