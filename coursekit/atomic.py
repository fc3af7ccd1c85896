"""Atomic file writes: a reader sees the old file or the complete new one, never half of one.

Each write happens under the output's lock (:mod:`coursekit.output_lock`): the caller's, when it
already holds one covering the path (a command that claimed its ``--out``), or one taken for the
duration of the write. The temporary's random name is recorded in that lock before it exists, so
the temporaries of a killed write are removed by the next write of the same path, and nothing else.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from coursekit.output_lock import OutputLock, lock_output


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = "", lock: OutputLock | None = None) -> Iterator[Path]:
    """Yield a temporary path (an empty file) for ``path``; on success it replaces ``path`` in one rename.

    If the body raises, the temporary file is removed and ``path`` is left exactly as it was.
    ``suffix`` keeps libraries that append extensions (``np.savez`` adds ``.npz``) honest.
    ``lock``: the caller's lock on ``path`` or on a folder holding it (default: lock ``path`` now).
    The file gets the mode a plain open() would give (0666 less the umask, not mkstemp's 0600).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        if lock is None:
            lock = stack.enter_context(lock_output(path))
        tmp = lock.new_temporary(path, ".tmp" + suffix)
        try:
            yield tmp
            with open(tmp, "rb+") as fh:  # flush to disk before the rename makes it visible
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        finally:
            lock.discard(tmp)  # after the rename there is nothing left to remove: only the record goes


def atomic_write_bytes(path: str | os.PathLike, data: bytes, lock: OutputLock | None = None) -> None:
    """Write ``data`` to ``path`` atomically (under ``lock``, see :func:`atomic_path`)."""
    with atomic_path(path, lock=lock) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | os.PathLike, text: str, lock: OutputLock | None = None) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (under ``lock``, see :func:`atomic_path`)."""
    atomic_write_bytes(path, text.encode("utf-8"), lock=lock)
