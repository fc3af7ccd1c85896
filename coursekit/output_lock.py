"""One writer per output: a lock beside it that also records the temporaries its holder makes.

Every write of an output (a run folder, a dataset, an evaluation summary, a grade folder, a zip)
first takes the output's lock, the hidden file ``.NAME.coursekit-lock`` beside ``NAME``, with
``flock(LOCK_EX | LOCK_NB)``. A second writer of the same output is refused at once, one line
naming the first one's PID. The kernel drops a flock when its process dies (SIGKILL included),
so a killed run leaves no stale lock: its file may stay, but the next writer locks it at once.

The lock file is also the marker that proves which hidden entries coursekit made. It is JSON::

    {"format": "coursekit-output-lock", "format_version": 1, "pid": 4242,
     "command": "coursekit train ...", "temporaries": [".run.3f9c...e1.tmp", ...]}

A temporary's name carries 128 random bits (``.NAME.<32 hex>.tmp[.ext]``, ``.NAME.<32 hex>.old``),
so no user's file has it, and it is written into the lock file BEFORE the temporary is created.
When a writer takes a lock whose file still lists temporaries, their writer died: those entries,
and only those, are removed (the leftover sweep). Nothing else beside an output is ever deleted,
whatever its name: a user's ``.run.backup_1.old`` or ``.demos.npz.20241201.old`` is never touched.

Releasing removes the lock file while still holding it, then closes it. A writer that opened the
file just before it was removed could then lock the removed inode; so after locking, the path must
still name the locked inode, or the writer opens it again (the unlink/reopen race).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import secrets
import shutil
import stat
import sys
import time
from collections.abc import Iterator
from pathlib import Path

try:
    import fcntl
except ImportError:  # Windows: no advisory locks; outputs are then checked but not locked
    fcntl = None

FORMAT = "coursekit-output-lock"
FORMAT_VERSION = 1
LOCK_SUFFIX = ".coursekit-lock"
_TEMPORARY = re.compile(r"\..+\.[0-9a-f]{32}\.(?:tmp|old)(?:\.[A-Za-z0-9]+)*", re.S)
"""The shape of every temporary's name; the sweep removes nothing of another shape, recorded or not."""


def lock_file_of(output: str | os.PathLike) -> Path:
    """The lock file of ``output``: ``.NAME.coursekit-lock`` in the same folder (a long NAME is shortened)."""
    output = Path(output)
    name = output.name
    if len(name) > 200:  # keep the lock's name within the 255 bytes a file name may have
        name = f"{name[:100]}.{hashlib.sha256(name.encode('utf-8', 'surrogateescape')).hexdigest()[:16]}"
    return output.parent / f".{name}{LOCK_SUFFIX}"


def lstat_or_none(path: Path) -> os.stat_result | None:
    """``os.lstat(path)`` (the entry itself, never a link's target), or None where nothing is there."""
    try:
        return os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None


def _remove(path: Path) -> bool:
    """Remove the file or folder ``path`` without following a link at it; False if there was nothing."""
    st = lstat_or_none(path)
    if st is None or stat.S_ISLNK(st.st_mode):
        return False  # coursekit never makes links: a link at a recorded name is left alone
    if stat.S_ISDIR(st.st_mode):
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)
    return True


def _read_record(fd: int) -> tuple[bytes, dict | None]:
    """(raw bytes, the parsed record or None) of an open lock file."""
    raw = os.pread(fd, 1 << 20, 0)
    try:
        record = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return raw, None
    return raw, record if isinstance(record, dict) and record.get("format") == FORMAT else None


class OutputLock:
    """An exclusive claim on one output path, held by this process until :meth:`close`.

    Temporaries for the output (or for anything inside it) are made with :meth:`new_temporary`,
    which records each name in the lock file before creating it, and removed with :meth:`discard`.
    ``swept`` lists what the leftover sweep removed when the lock was taken.
    """

    def __init__(self, output: Path, lock_file: Path, fd: int, shown: str) -> None:
        self.output, self.lock_file, self._fd, self._shown = output, lock_file, fd, shown
        self.directory = output.parent
        """Where the lock file is, and where temporaries go (beside the output)."""
        self.temporaries: list[str] = []
        """Names of this holder's temporaries, relative to ``directory``."""
        self.swept: list[Path] = []
        self.created_dirs: list[Path] = []
        """Folders made to hold the output; removed again on close if they stayed empty."""

    # -- the record -----------------------------------------------------------------------------
    def _write(self) -> None:
        record = {"format": FORMAT, "format_version": FORMAT_VERSION, "pid": os.getpid(),
                  "command": " ".join(["coursekit" if "coursekit" in sys.argv[0] else Path(sys.argv[0]).name]
                                      + sys.argv[1:])[:300],
                  "output": self.output.name, "temporaries": self.temporaries}
        data = (json.dumps(record, indent=1) + "\n").encode("utf-8")
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, data, 0)

    def _relative(self, path: Path) -> str:
        rel = os.path.relpath(path, self.directory)
        if os.path.isabs(rel) or ".." in Path(rel).parts or not _TEMPORARY.fullmatch(Path(rel).name):
            raise ValueError(f"{str(path)!r} is not a temporary of {str(self.output)!r}")
        return rel

    def new_temporary(self, target: str | os.PathLike, suffix: str = ".tmp", directory: bool = False) -> Path:
        """Create a new, recorded, empty file (or folder) to become ``target``; return its path.

        ``target`` is the output or a path inside it. The temporary goes beside the output (on
        ``target``'s own file system if the output's folder is on another one); ``suffix`` is
        ``.tmp``, ``.tmp.EXT`` (for libraries that check extensions) or ``.old``.
        """
        target = Path(target)
        where = self.directory
        if target.parent != where and os.stat(target.parent).st_dev != os.stat(where).st_dev:
            where = target.parent  # a rename cannot cross file systems
        path = where / f".{target.name[:64]}.{secrets.token_hex(16)}{suffix}"
        self.temporaries.append(self._relative(path))
        self._write()  # recorded before it exists: a kill at any moment leaves nothing unrecorded
        if directory:
            os.mkdir(path, 0o777)  # the umask applies, as for any folder the user makes
        else:
            os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666))
        return path

    def discard(self, path: str | os.PathLike) -> None:
        """Remove the temporary ``path`` if it is still there, and forget it."""
        path = Path(path)
        rel = self._relative(path)
        if rel in self.temporaries:
            _remove(path)
            self.temporaries.remove(rel)
            self._write()

    # -- the sweep ------------------------------------------------------------------------------
    def _sweep(self, record: dict | None) -> None:
        """Remove the temporaries a dead holder recorded (after putting back an output it had moved aside)."""
        names = record.get("temporaries") if record else None
        for rel in names if isinstance(names, list) else []:
            if not isinstance(rel, str) or ".." in Path(rel).parts or os.path.isabs(rel) \
                    or not _TEMPORARY.fullmatch(Path(rel).name):
                continue  # not a name coursekit gives: never touched, whatever the file says
            path = self.directory / rel
            previous = path / "previous"
            if rel.endswith(".old") and lstat_or_none(self.output) is None and previous.is_dir() and not previous.is_symlink():
                os.replace(previous, self.output)  # killed between the two renames of replace_dir's fallback
            if _remove(path):
                self.swept.append(path)

    # -- taking and releasing -------------------------------------------------------------------
    @classmethod
    def acquire(cls, output: str | os.PathLike, shown: str | None = None) -> OutputLock:
        """Lock ``output`` (its folder is created if missing) or raise ValueError naming the holder's PID."""
        output = Path(output)
        shown = shown or repr(str(output))
        created = _make_dirs(output.parent)
        try:
            lock = cls._open_locked(output, shown)
        except BaseException:
            _remove_empty(created)
            raise
        lock.created_dirs = created
        return lock

    @classmethod
    def _open_locked(cls, output: Path, shown: str) -> OutputLock:
        lock_file = lock_file_of(output)
        for _ in range(100):  # each retry follows a holder that released between our open and our lock
            st = lstat_or_none(lock_file)
            if st is not None and not stat.S_ISREG(st.st_mode):
                raise ValueError(f"{shown}: {str(lock_file)!r} exists and is not coursekit's lock file (it is not a "
                                 f"regular file); remove it, or choose another path")
            fd = os.open(lock_file, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o666)
            try:
                if fcntl is not None:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    os.close(fd)
                    raise
                holder = _holder(fd)
                os.close(fd)
                raise ValueError(busy(shown, holder)) from None
            now = lstat_or_none(lock_file)
            if now is None or (now.st_ino, now.st_dev) != (os.fstat(fd).st_ino, os.fstat(fd).st_dev):
                os.close(fd)  # the holder removed this file after we opened it: lock the one there now
                continue
            raw, record = _read_record(fd)
            if raw.strip() and record is None:
                os.close(fd)
                raise ValueError(f"{shown}: {str(lock_file)!r} exists and was not written by coursekit; remove it, "
                                 f"or choose another path")
            lock = cls(output, lock_file, fd, shown)
            try:
                lock._sweep(record)
                lock._write()
            except BaseException:
                lock.close()
                raise
            return lock
        raise OSError(errno.EAGAIN, f"could not take the lock {str(lock_file)!r}: it keeps being replaced")

    def close(self) -> None:
        """Remove what is left of this holder's temporaries and the lock file, then release the lock."""
        if self._fd < 0:
            return
        try:
            for rel in list(self.temporaries):
                _remove(self.directory / rel)
            self.temporaries.clear()
            now = lstat_or_none(self.lock_file)
            if now is not None and (now.st_ino, now.st_dev) == (os.fstat(self._fd).st_ino, os.fstat(self._fd).st_dev):
                self.lock_file.unlink()  # while still locked: nobody can be holding the file we remove
        finally:
            os.close(self._fd)
            self._fd = -1
            if lstat_or_none(self.output) is None:
                _remove_empty(self.created_dirs)

    def __enter__(self) -> OutputLock:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def busy(shown: str, holder: str) -> str:
    """The one line that refuses a second writer of an output."""
    return f"{shown} is being written by another coursekit process ({holder}); wait for it to finish, or choose another path"


def holder_of(output: str | os.PathLike) -> str | None:
    """"PID n: command" of a live process holding ``output``'s lock, else None. Writes nothing, waits for nothing."""
    lock_file = lock_file_of(output)
    try:
        st = os.lstat(lock_file)
        if fcntl is None or not stat.S_ISREG(st.st_mode):
            return None
        fd = os.open(lock_file, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:  # no lock file, or no way to it (a link loop...): nobody is writing there
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # granted at once unless a writer holds it exclusively
    except OSError:
        return _holder(fd)
    finally:
        os.close(fd)  # also drops the shared lock, if it was granted
    return None


def _holder(fd: int) -> str:
    """"PID n: command" of the process holding the lock file ``fd`` (it may still be writing it)."""
    deadline = time.monotonic() + 1.0
    while True:
        record = _read_record(fd)[1]
        if record is not None and isinstance(record.get("pid"), int):
            return f"PID {record['pid']}: {record.get('command', '?')}"
        if time.monotonic() > deadline:
            return "its PID is not recorded yet"
        time.sleep(0.02)


def _make_dirs(folder: Path) -> list[Path]:
    """``mkdir -p folder``; returns the folders it created, outermost first."""
    missing = []
    while lstat_or_none(folder) is None and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    for path in reversed(missing):
        with contextlib.suppress(FileExistsError):
            path.mkdir()
    return list(reversed(missing))


def _remove_empty(folders: list[Path]) -> None:
    for path in reversed(folders):
        with contextlib.suppress(OSError):
            path.rmdir()  # only if still empty: anything someone put there stays


@contextlib.contextmanager
def lock_output(output: str | os.PathLike, shown: str | None = None) -> Iterator[OutputLock]:
    """``with lock_output(path) as lock:`` -- :meth:`OutputLock.acquire` ... :meth:`OutputLock.close`."""
    lock = OutputLock.acquire(output, shown)
    try:
        yield lock
    finally:
        lock.close()
