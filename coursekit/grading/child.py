"""The trusted test process's plumbing: its result pipe and its end.

Helpers of :mod:`coursekit.grading.runner` (the parent side of a grading run).
"""

from __future__ import annotations

import os
import signal
import subprocess

MAX_PIPE_BYTES = 8 * 1024 * 1024
"""The parent stops storing result messages beyond this many bytes."""


def _kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL the trusted test process's session (its workers die with it: --die-with-parent)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        proc.kill()
    except ProcessLookupError:
        pass
    proc.wait()


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
