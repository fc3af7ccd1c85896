"""Safe outputs: paths checked before work, directories replaced atomically, leftovers of killed runs cleaned.

:func:`check_output` refuses, before any work, an output path that would destroy an input or
something coursekit did not write, and an existing output of its own without ``overwrite``.

A command writes a directory output (a checkpoint) into a hidden staging directory beside it,
``.NAME.XXXXXXXX.tmp``, and then swaps it into place::

    with staging_dir(path) as tmp:      # .NAME.k3j9x1.tmp, locked by this process while it lives
        ...write files into tmp...
        replace_dir(tmp, path)          # one atomic exchange: path is the old or the new, never neither

On Linux the swap is ``renameat2(RENAME_EXCHANGE)``: at every instant ``path`` is either the old
complete directory or the new complete one, whatever moment the process is killed at. Elsewhere
(macOS, or a file system without the call) the old directory is first renamed aside to
``.NAME.XXXXXXXX.old``; a kill between the two renames leaves it there, and the next
:func:`clean_leftovers` puts it back.

A SIGKILLed run cannot tidy up, so :func:`clean_leftovers` (called by the next write to the same
place) removes the hidden ``.NAME.*.tmp`` / ``.NAME.*.old`` entries that runs of coursekit left —
only names of that shape, and never a staging directory a live process still holds (each staging
directory carries an advisory ``flock`` that dies with its process).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

try:
    import fcntl
except ImportError:  # Windows: no advisory locks; leftovers are then cleaned without the liveness check
    fcntl = None

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


_RANDOM = r"(?:[a-z0-9_]{8}|[0-9a-f]{32})"
"""The random part of a temporary's name: tempfile.mkdtemp's 8 characters or atomic_path's uuid4 hex."""


def _leftover_pattern(name: str) -> re.Pattern[str]:
    """Hidden names coursekit's writers give their temporaries for ``name``: ``.NAME.<random>.tmp[.ext]``,
    ``.NAME.<random>.old``, and a checkpoint's staging folder inside a run's (``..NAME.<random>.tmp.<random>.tmp``).
    The random part has the exact shape coursekit draws, so a user's ``.NAME.backup.old`` never matches."""
    n = re.escape(name)
    return re.compile(rf"\.{n}\.{_RANDOM}\.(?:tmp|old)(?:\.[A-Za-z0-9]+)?|\.\.{n}\.{_RANDOM}\.tmp\.{_RANDOM}\.tmp")


def _lock(path: Path) -> int | None:
    """An exclusive advisory lock on the directory ``path`` (fd), or None if another process holds it."""
    if fcntl is None:
        return -1
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return fd


@contextlib.contextmanager
def staging_dir(path: str | os.PathLike) -> Iterator[Path]:
    """A new hidden directory beside ``path``, locked while this process lives; removed on exit if still there."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    fd = _lock(tmp)
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if fd is not None and fd >= 0:
            os.close(fd)


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap the paths ``a`` and ``b`` (Linux renameat2); False where the call is unavailable."""
    libc_name = ctypes.util.find_library("c")
    if not libc_name or not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(libc_name, use_errno=True)
    fn = getattr(libc, "renameat2", None)
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL / ENOSYS / EOPNOTSUPP: this file system cannot exchange
        return False
    raise OSError(err, os.strerror(err), str(b))


def replace_dir(new: str | os.PathLike, path: str | os.PathLike) -> None:
    """Make the complete directory ``new`` appear at ``path``; any old ``path`` ends up at ``new``.

    ``path`` is never missing or partial at any instant on Linux (atomic exchange); elsewhere the
    old directory waits in a hidden ``.old`` sibling between two renames (see :func:`clean_leftovers`).
    """
    new, path = Path(new), Path(path)
    if not path.exists():
        os.replace(new, path)
        return
    if not path.is_dir() or path.is_symlink():
        raise ValueError(f"{str(path)!r} exists and is not a directory; refusing to replace it")
    if _exchange(new, path):
        return
    old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
    os.replace(path, old / "previous")
    os.replace(new, path)
    os.replace(old / "previous", new)  # the caller's staging dir now holds the old one, as after an exchange
    old.rmdir()


def clean_leftovers(path: str | os.PathLike) -> list[Path]:
    """Remove the temporaries killed coursekit runs left beside ``path``; returns what was removed.

    Only hidden ``.NAME.<random>.tmp[.ext]`` / ``.NAME.<random>.old`` entries are touched, and
    never one a live process still holds. If ``path`` itself is missing because a run was killed
    between the two renames of the non-Linux swap, the old directory is moved back first.
    """
    path = Path(path)
    if not path.parent.is_dir():
        return []
    pattern = _leftover_pattern(path.name)
    removed = []
    for entry in sorted(path.parent.iterdir()):
        if not pattern.fullmatch(entry.name) or entry.is_symlink():
            continue
        if entry.is_dir():
            fd = _lock(entry)
            if fd is None:
                continue  # a live run is writing there
            try:
                previous = entry / "previous"
                if entry.name.endswith(".old") and previous.is_dir() and not path.exists():
                    os.replace(previous, path)
                shutil.rmtree(entry, ignore_errors=True)
            finally:
                if fd >= 0:
                    os.close(fd)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry)
    return removed


def check_output(path: str | os.PathLike, *, what: str, is_ours: Callable[[Path], bool], directory: bool,
                 overwrite: bool = False, inputs: Iterable[str | os.PathLike | None] = (), flag: str = "--out") -> Path:
    """Check an output path BEFORE any work starts; ValueError (one line naming ``flag`` and the path) if unsafe.

    Refused: the path is (or is inside) one of ``inputs``, or a directory output would contain
    one; the nearest existing ancestor is a file or not writable; the path is a link; a file
    where a directory is wanted or the reverse; something that exists and is not ours
    (``is_ours(path)`` False: a user's folder or file, never deleted); one of ours without
    ``overwrite``. Allowed: a new path, an empty directory (directory outputs), and with
    ``overwrite`` an existing output of this kind, which the writer then replaces atomically.
    """
    path = Path(path)
    shown = f"{flag} {str(path)!r}"
    target = path.resolve()
    for given in inputs:
        if given is None:
            continue
        source = Path(given).resolve()
        if target == source or source in target.parents:
            raise ValueError(f"{shown} is the input {str(given)!r} or inside it: writing there would destroy the "
                             f"input; choose another path")
        if directory and target in source.parents:
            raise ValueError(f"{shown} contains the input {str(given)!r}: choose an output path outside the inputs")
    ancestor = target.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ValueError(f"{shown}: {str(ancestor)!r} is a file, so nothing can be written inside it; choose another path")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ValueError(f"{shown}: the directory {str(ancestor)!r} is not writable")
    if path.is_symlink():
        raise ValueError(f"{shown} is a symbolic link; give the real path (coursekit never writes through links)")
    if not path.exists():
        return path
    if directory and not path.is_dir():
        raise ValueError(f"{shown} exists and is a file, not a {what}; refusing to replace it: choose another path")
    if not directory and path.is_dir():
        raise ValueError(f"{shown} is a directory; it must name a {what} file (nothing in the directory is touched)")
    if directory and not any(path.iterdir()):
        return path
    if not is_ours(path):
        if directory:
            names = sorted(p.name for p in path.iterdir())
            held = f" (it holds {', '.join(names[:4])}{', ...' if len(names) > 4 else ''})"
        else:
            held = ""
        raise ValueError(f"{shown} exists and is not a {what}{held}; refusing to replace it: choose another path")
    if not overwrite:
        raise ValueError(f"{shown} already holds a {what}; pass --overwrite to replace it (the old one stays "
                         f"until the new one is complete)")
    return path
