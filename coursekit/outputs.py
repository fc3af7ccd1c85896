"""The output policy: every command that writes checks its outputs first, locks them, and never touches a user's file.

One policy for ``coursekit train --out``, ``collect --out``, ``eval --json`` / ``--record``,
``demo --out``, ``grade SUBMISSIONS --out`` and ``grade --gradescope-autograder``:

1. **Checked before any work** (:func:`check_output`; one line naming the flag and the path, exit
   status 2, nothing written). Refused: the current folder (``--out .``; ``--out ''`` is refused by
   the argument parser) or the root; a path that is, is inside, or contains one of the command's
   inputs (the data, the checkpoint, the submissions folder and every student folder in it, the
   hidden tests); a symbolic link at the path (a dangling one and a loop included) or a loop on
   the way to it; a FIFO, socket, device or any other non-regular file (never opened, so never
   waited on); a path under a file; a folder that is not writable; a file where a folder is
   wanted and the reverse; something that exists and is not provably an output of this kind
   written by coursekit (the refusal names the foreign file); one that is, without
   ``--overwrite`` (commands whose help says so replace their own earlier output without it).
2. **Locked** (:func:`claim_output`, :mod:`coursekit.output_lock`): the output's lock file
   ``.NAME.coursekit-lock`` is ``flock``-ed before any work and held to the end; a second writer of
   the same output is refused at once, naming the first one's PID. The lock dies with its process,
   so a SIGKILLed run leaves no stale lock. The check runs again once the lock is held.
3. **Temporaries** carry 128 random bits in their names (``.NAME.<32 hex>.tmp``) and are recorded
   in the lock file before they are created. The next writer of the same output removes exactly
   the recorded ones a dead writer left (the leftover sweep) and nothing else, whatever its name.
4. **Atomic**: a file is written to a temporary and renamed over the old one
   (:func:`coursekit.atomic.atomic_path`); a folder is built in a temporary folder and swapped in::

       with claim_output(path, ...) as lock:   # checked, locked, leftovers of killed runs removed
           with staging_dir(path, lock) as tmp:
               ...write files into tmp...
               replace_dir(tmp, path, lock)    # path is the old folder or the new one, never neither

   On Linux the swap is ``renameat2(RENAME_EXCHANGE)``: at every instant ``path`` is the old
   complete folder or the new complete one, whatever moment the process is killed at. Elsewhere
   (macOS, or a file system without the call) the old folder is first moved into a recorded
   ``.NAME.<32 hex>.old`` folder; a kill between the two renames leaves it there, and the next
   writer's sweep puts it back.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import os
import stat
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from coursekit.output_lock import OutputLock, busy, holder_of, lock_output, lstat_or_none

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100

Foreign = Callable[[Path], "str | None"]
"""Given an existing output path: None if it is provably one coursekit wrote, else why not (naming the foreign file)."""


def kind_of(mode: int) -> str:
    """What a file of this ``st_mode`` is, in words (for messages)."""
    for test, name in ((stat.S_ISREG, "file"), (stat.S_ISDIR, "folder"), (stat.S_ISLNK, "symbolic link"),
                       (stat.S_ISFIFO, "FIFO (named pipe)"), (stat.S_ISSOCK, "socket"),
                       (stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device")):
        if test(mode):
            return name
    return "special file"


def regular_file(path: str | os.PathLike) -> bool:
    """True if ``path`` is a regular file itself (not a link, FIFO, device...): safe to open and read."""
    st = lstat_or_none(Path(path))
    return st is not None and stat.S_ISREG(st.st_mode)


def _resolve(path: Path, shown: str) -> Path:
    """``path`` with every link resolved; a loop on the way is named in a ValueError."""
    try:
        return path.resolve()
    except (RuntimeError, OSError):
        for i in range(1, len(path.parts) + 1):
            prefix = Path(*path.parts[:i])
            try:
                os.stat(prefix)
            except OSError as exc:
                if exc.errno == errno.ELOOP:
                    raise ValueError(f"{shown}: {str(prefix)!r} is a symbolic-link loop; give a real path") from None
                break
        raise ValueError(f"{shown} cannot be resolved to a real path") from None


def _refuse_link(path: Path, shown: str) -> None:
    target = os.readlink(path)
    try:
        os.stat(path)
        what = f"to {target!r}"
    except OSError as exc:
        what = f"to {target!r}, a loop" if exc.errno == errno.ELOOP else f"to {target!r}, which does not exist"
    raise ValueError(f"{shown} is a symbolic link ({what}); coursekit never writes through links: give a real path")


def check_output(path: str | os.PathLike, *, what: str, foreign: Foreign | None, directory: bool,
                 overwrite: bool = False, inputs: Iterable[str | os.PathLike | None] = (), flag: str = "--out") -> Path:
    """Check an output path BEFORE any work; ValueError (one line naming ``flag`` and the path) if unsafe.

    ``foreign(path)`` decides whether an existing output is coursekit's (see :data:`Foreign`);
    ``foreign=None`` means an existing one is never replaced (an empty folder is still accepted).
    Allowed: a new path, an empty folder (``directory``), and with ``overwrite`` an output of this
    kind that coursekit wrote. Everything refused is listed in this module's docstring.
    """
    path = Path(path)
    shown = f"{flag} {str(path)!r}"
    try:
        st = os.lstat(path)
    except OSError:
        st = None  # missing, or the way to it is broken: _resolve says which
    if st is not None and stat.S_ISLNK(st.st_mode):
        _refuse_link(path, shown)
    target = _resolve(path, shown)
    if target == Path.cwd().resolve() or target.parent == target:
        place = "the current folder" if target.parent != target else "the root of the file system"
        raise ValueError(f"{shown} is {place}; name a new {'folder' if directory else 'file'} inside it")
    for given in inputs:
        if given is None:
            continue
        source = _resolve(Path(given), f"input {str(given)!r}")
        if target == source:
            raise ValueError(f"{shown} is the input {str(given)!r}: writing there would destroy it; choose another path")
        if source in target.parents:
            raise ValueError(f"{shown} is inside the input {str(given)!r}: writing there would change the input; "
                             f"choose a path outside it")
        if directory and target in source.parents:
            raise ValueError(f"{shown} contains the input {str(given)!r}: choose an output path outside the inputs")
    ancestor = target.parent
    while (up := lstat_or_none(ancestor)) is None:
        ancestor = ancestor.parent
    if not stat.S_ISDIR(up.st_mode):
        raise ValueError(f"{shown}: {str(ancestor)!r} is a {kind_of(up.st_mode)}, so nothing can be written inside it; "
                         f"choose another path")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ValueError(f"{shown}: the folder {str(ancestor)!r} is not writable")
    st = lstat_or_none(path)
    if st is None:
        return path
    return _check_existing(path, st, shown, what=what, foreign=foreign, directory=directory, overwrite=overwrite)


def _check_existing(path: Path, st: os.stat_result, shown: str, *, what: str, foreign: Foreign | None,
                    directory: bool, overwrite: bool) -> Path:
    """The part of :func:`check_output` for a path that exists (and is not a link)."""
    if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        raise ValueError(f"{shown} is a {kind_of(st.st_mode)}, not a regular {'folder' if directory else 'file'}; "
                         f"coursekit never writes to one: choose another path")
    if directory and not stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{shown} exists and is a file, not a {what}; refusing to replace it: choose another path")
    if not directory and stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{shown} is a directory; it must name a {what} file (nothing in the directory is touched)")
    if directory:
        if not os.access(path, os.W_OK | os.X_OK):
            raise ValueError(f"{shown}: the folder is not writable")
        if not any(path.iterdir()):
            return path
    if foreign is None:
        held = f" and holds {min(p.name for p in path.iterdir())!r}" if directory else ""
        raise ValueError(f"{shown} already exists{held}: choose a new {'or empty folder' if directory else 'name'} "
                         f"(coursekit never replaces it)")
    reason = foreign(path)
    if reason:
        raise ValueError(f"{shown} exists and is not a {what} ({reason}); refusing to replace it: choose another path")
    if not overwrite:
        raise ValueError(f"{shown} already holds a {what}; pass --overwrite to replace it (the old one stays "
                         f"until the new one is complete)")
    return path


@contextlib.contextmanager
def claim_output(path: str | os.PathLike, *, what: str, foreign: Foreign | None, directory: bool,
                 overwrite: bool = False, inputs: Iterable[str | os.PathLike | None] = (),
                 flag: str = "--out") -> Iterator[OutputLock]:
    """Check ``path`` (:func:`check_output`), lock it, check it again under the lock; yield the lock.

    The lock's ``swept`` lists the temporaries of killed earlier writers it removed.
    """
    inputs = list(inputs)
    args = dict(what=what, foreign=foreign, directory=directory, overwrite=overwrite, inputs=inputs, flag=flag)
    shown = f"{flag} {str(path)!r}"
    try:
        path = check_output(path, **args)
    except ValueError:
        holder = holder_of(path)  # a refusal of what a live writer is writing right now: name that writer
        if holder is not None:
            raise ValueError(busy(shown, holder)) from None
        raise
    with lock_output(path, shown=shown) as lock:
        check_output(path, **args)  # something may have appeared between the first check and the lock
        yield lock


@contextlib.contextmanager
def staging_dir(path: str | os.PathLike, lock: OutputLock) -> Iterator[Path]:
    """A new recorded hidden folder beside ``path`` (under ``lock``); removed on exit if still there."""
    tmp = lock.new_temporary(Path(path), ".tmp", directory=True)
    try:
        yield tmp
    finally:
        lock.discard(tmp)


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
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):  # this file system cannot exchange
        return False
    raise OSError(err, os.strerror(err), str(b))


def replace_dir(new: str | os.PathLike, path: str | os.PathLike, lock: OutputLock) -> None:
    """Make the complete folder ``new`` appear at ``path``; any old ``path`` ends up at ``new``.

    ``path`` is never missing or partial at any instant on Linux (atomic exchange); elsewhere the
    old folder waits in a recorded ``.old`` temporary between two renames (see the module docstring).
    """
    new, path = Path(new), Path(path)
    st = lstat_or_none(path)
    if st is None:
        os.replace(new, path)
        return
    if not stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{str(path)!r} exists and is not a directory; refusing to replace it")
    if _exchange(new, path):
        return
    old = lock.new_temporary(path, ".old", directory=True)
    os.replace(path, old / "previous")
    os.replace(new, path)
    os.replace(old / "previous", new)  # the caller's staging folder now holds the old one, as after an exchange
    lock.discard(old)
