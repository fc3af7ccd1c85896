"""How a worker process is started: inside bubblewrap where it works, else with today's safety net.

With ``bwrap`` (Debian/Ubuntu package ``bubblewrap``) every worker gets new user, PID, mount,
IPC, UTS and network namespaces and sees only: the system's ``/usr`` and ``/etc`` and the Python
installation (read-only), the ``coursekit`` package (read-only, with the graded exercise's
reference blanked out), the one student module (read-only) and a private tmpfs of
``disk_mb`` MiB as its only writable place (``/tmp``, also its $HOME). ``solutions/``,
``tests/``, the instructor's $HOME, the output folder and other students' folders are not
there at all. ``--die-with-parent`` and the PID namespace take every process it started down
with it; it cannot see, signal or outlive the grader. As root, bwrap runs as a user id of its
own per worker (100000 + the trusted process's pid) where every mounted folder is reachable by
that user, so RLIMIT_NPROC counts only its processes (see :func:`sandbox_uid`).

Without bwrap (macOS, a container without user namespaces, or ``COURSEKIT_SANDBOX=none``) the
worker is a plain subprocess in its own session with the resource limits, a minimal environment
and a scratch folder: the trust split still holds, OS-level isolation does not (README,
"threat model"). ``COURSEKIT_SANDBOX=bwrap`` makes a missing bwrap an error instead.
"""

from __future__ import annotations

import functools
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

MODE_ENV = "COURSEKIT_SANDBOX"
"""Environment variable: "auto" (default: bwrap when it works), "bwrap" (required) or "none"."""
NOT_ISOLATED = ("coursekit grade: bubblewrap (bwrap) is not available here: student code runs WITHOUT "
                "OS isolation (no namespaces, no private filesystem); see README 'threat model'")

PACKAGE_DIR = Path(__file__).resolve().parents[1]
"""The coursekit package folder (only this is mounted, never the repository around it)."""


def _system_dirs() -> list[tuple[str, str]]:
    """("bind" | "symlink", path or target) for the top-level system folders the interpreter needs."""
    out = []
    for name in ("/usr", "/etc", "/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32"):
        if os.path.islink(name):
            out.append(("symlink", name))
        elif os.path.isdir(name):
            out.append(("bind", name))
    return out


def python_dirs() -> list[str]:
    """Folders holding the interpreter and its packages (resolved, deduplicated, outside /usr)."""
    dirs = []
    for p in {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix}:
        real = os.path.realpath(p)
        if not real.startswith(("/usr/", "/etc/")) and real != "/usr" and real not in dirs:
            dirs.append(real)
    return sorted(dirs)


def worker_python() -> str:
    """The interpreter path the worker runs: the venv's own (so its site-packages apply), resolved folder."""
    return str(Path(os.path.realpath(sys.prefix)) / "bin" / Path(sys.executable).name)


@functools.lru_cache(maxsize=None)
def bwrap_works(as_uid: int | None) -> bool:
    """One quick sandboxed `python -c pass` with the real mount layout."""
    exe = shutil.which("bwrap")
    if exe is None:
        return False
    cmd, fds = bwrap_command(exe, Path("/nonexistent"), 16, [], [worker_python(), "-I", "-c", "pass"])
    try:
        proc = subprocess.run(cmd, pass_fds=fds, capture_output=True, timeout=60, **_user_kwargs(as_uid))
    except (OSError, subprocess.SubprocessError):
        return False
    finally:
        for fd in fds:
            os.close(fd)
    return proc.returncode == 0


def _user_kwargs(uid: int | None) -> dict:
    return {} if uid is None else {"user": uid, "group": uid, "extra_groups": []}


def sandbox_uid() -> int | None:
    """As root: a user id of this trusted process's own (so RLIMIT_NPROC and file permissions are per
    worker), when bwrap can run as that user here (every mounted folder reachable by it); else None:
    bwrap runs as the grader's user and the sandbox's user maps to it (the kernel exempts root from
    RLIMIT_NPROC, so then the process count is capped by the trusted side's polling only)."""
    if os.geteuid() != 0 or not bwrap_works(100000):
        return None
    return 100000 + os.getpid()


def mode() -> str:
    """"bwrap" or "none": what workers started by this process get."""
    choice = os.environ.get(MODE_ENV, "auto").strip().lower() or "auto"
    if choice not in ("auto", "bwrap", "none"):
        raise ValueError(f"{MODE_ENV} must be auto, bwrap or none, got {choice!r}")
    if choice == "none":
        return "none"
    if bwrap_works(None) or (os.geteuid() == 0 and bwrap_works(100000)):
        return "bwrap"
    if choice == "bwrap":
        raise RuntimeError(f"{MODE_ENV}=bwrap but bubblewrap does not work here (is the `bubblewrap` package "
                           "installed and are user namespaces allowed?)")
    return "none"


def bwrap_command(exe: str, module_dir: Path, disk_mb: int, blanked: list[tuple[int, str]],
                  argv: list[str], env: dict[str, str] | None = None) -> tuple[list[str], list[int]]:
    """(command, fds to pass): bind sources are opened here (as the grader) and handed over as file
    descriptors, so the sandbox's own user needs no access to the folders around them."""
    cmd = [exe, "--unshare-all", "--unshare-user", "--die-with-parent", "--new-session", "--cap-drop", "ALL",
           "--uid", "65534", "--gid", "65534", "--hostname", "sandbox", "--clearenv"]
    fds: list[int] = []
    # the private tmpfs first: a library or interpreter under /tmp is then bound on top of it
    # /dev read-only (its device nodes still work): bwrap's /dev is a tmpfs the sandbox user owns
    cmd.extend(["--dev", "/dev", "--remount-ro", "/dev", "--proc", "/proc",
                "--size", str(int(disk_mb) * 1024 * 1024), "--tmpfs", "/tmp", "--dir", "/tmp/home", "--dir", "/tmp/work"])

    def bind(path: str, dest: str | None = None) -> None:
        fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
        os.set_inheritable(fd, True)
        fds.append(fd)
        cmd.extend(["--ro-bind-fd", str(fd), dest or path])

    for kind, path in _system_dirs():
        if kind == "symlink":
            cmd.extend(["--symlink", os.readlink(path), path])
        else:
            bind(path)
    for path in python_dirs():
        bind(path)
    bind(str(PACKAGE_DIR))
    for fd, dest in blanked:  # the graded exercise's library file, reference replaced by a raise
        cmd.extend(["--ro-bind-data", str(fd), dest])
        fds.append(fd)
        cache = Path(dest).parent / "__pycache__"
        if cache.is_dir():  # the compiled original must not be readable either: an empty read-only tmpfs
            cmd.extend(["--size", "4096", "--tmpfs", str(cache), "--remount-ro", str(cache)])
    if module_dir.is_dir():
        bind(str(module_dir), "/submission")
    cmd.extend(["--chdir", "/tmp/work"])
    for key, value in (env or {}).items():
        cmd.extend(["--setenv", key, value])
    return cmd + argv, fds


def kill_process(proc: subprocess.Popen) -> None:
    for target in (lambda: os.killpg(proc.pid, signal.SIGKILL), proc.kill):
        try:
            target()
        except (ProcessLookupError, PermissionError, OSError):
            pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass


def become_subreaper() -> None:
    """Orphans of a worker (a double-forked daemon) become our children, so we can end them."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):
        pass


def kill_orphans() -> None:
    """SIGKILL every remaining descendant of this process (workers' leftovers)."""
    try:
        import psutil

        for child in psutil.Process().children(recursive=True):
            try:
                child.kill()
            except psutil.Error:
                pass
        for child in psutil.Process().children(recursive=False):
            try:
                child.wait(timeout=1)
            except psutil.Error:
                pass
    except Exception:  # noqa: BLE001 - best effort (psutil missing, races)
        pass


def tree_usage(pid: int) -> tuple[float, int]:
    """(resident MiB, process count) of the worker's whole tree (bwrap's own processes included)."""
    try:
        import psutil

        proc = psutil.Process(pid)
        procs = [proc, *proc.children(recursive=True)]
        return sum(p.memory_info().rss for p in procs) / 2**20, len(procs)
    except Exception:  # noqa: BLE001 - the process may be gone between the calls
        return 0.0, 0
