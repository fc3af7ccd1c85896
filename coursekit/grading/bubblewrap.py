"""How an untrusted worker process runs: inside bubblewrap where it works, else plainly; watched, stopped.

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

:class:`WorkerProcess` starts one worker either way (the code it runs: :mod:`coursekit.grading.worker`)
and keeps the tail of what it prints; :class:`coursekit.grading.sandbox.Sandbox` talks to it.
"""

from __future__ import annotations

import functools
import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

from coursekit.grading.build import blank_reference
from coursekit.grading.exercises import Exercise

MODE_ENV = "COURSEKIT_SANDBOX"
"""Environment variable: "auto" (default: bwrap when it works), "bwrap" (required) or "none"."""
NOT_ISOLATED = ("coursekit grade: bubblewrap (bwrap) is not available here: student code runs WITHOUT "
                "OS isolation (no namespaces, no private filesystem); see README 'threat model'")

PACKAGE_DIR = Path(__file__).resolve().parents[1]
"""The coursekit package folder (only this is mounted, never the repository around it)."""
OUTPUT_TAIL = 4000
"""Characters of printed output kept per test."""
_WORKER_CODE = "import sys; sys.path.insert(0, {root!r}); from coursekit.grading.worker import main; sys.exit(main())"


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
    """SIGKILL ``proc``'s session (a worker, or the trusted test process whose workers die with it) and
    wait for it (at most 10 s)."""
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


class PrintedOutput:
    """What a sandbox's workers print during one test: the tail, and a byte count against the limit."""

    def __init__(self, limit_bytes: int) -> None:
        self.limit = limit_bytes
        self._lock = threading.Lock()
        self._tail = bytearray()
        self._count = 0

    def reset(self, keep_tail: bool = False) -> None:
        """A new test (clears the tail too) or a new worker (``keep_tail``: the count starts over)."""
        with self._lock:
            self._count = 0
            if not keep_tail:
                self._tail.clear()

    def add(self, chunk: bytes) -> bool:
        """Keep ``chunk``; False once more than the limit was printed."""
        with self._lock:
            self._tail.extend(chunk)
            if len(self._tail) > 4 * OUTPUT_TAIL:
                del self._tail[: len(self._tail) - OUTPUT_TAIL]
            self._count += len(chunk)
            return self._count <= self.limit

    def tail(self) -> str:
        with self._lock:
            return bytes(self._tail[-OUTPUT_TAIL:]).decode("utf-8", errors="replace")


class WorkerProcess:
    """One started worker: requests go to ``req_w``, replies come from ``rep_r`` (non-blocking), what it
    prints goes to ``output``. Its settings message (the first request) is the caller's to send."""

    def __init__(self, exercise: Exercise, work: Path, source: Path, *, mode: str, disk_mb: int, output: PrintedOutput,
                 tag: str) -> None:
        self.mode, self.output = mode, output
        self.over_output = False
        """True when it was stopped for printing more than the output limit."""
        module_dir = self._stage(work, source)
        self.folder = "/submission" if mode == "bwrap" else str(module_dir)
        """Where the worker finds the student's module."""
        req_r, self.req_w = os.pipe()
        self.rep_r, rep_w = os.pipe()
        out_r, out_w = os.pipe()
        self.reply_fd = rep_w
        """The reply pipe's number in the worker (its settings message names it)."""
        os.set_inheritable(rep_w, True)
        fds: list[int] = []
        try:
            cmd, env, fds, kwargs = self._command(exercise, work, module_dir, disk_mb, tag)
            self.own_user = "user" in kwargs
            """Runs as a user id of its own (RLIMIT_NPROC then counts only its processes)."""
            self.proc = subprocess.Popen(cmd, stdin=req_r, stdout=out_w, stderr=out_w, pass_fds=(rep_w, *fds), env=env,
                                         start_new_session=True, **kwargs)
        except BaseException:
            for fd in (self.req_w, self.rep_r, out_r):
                os.close(fd)
            raise
        finally:
            for fd in (req_r, rep_w, out_w, *fds):
                os.close(fd)
        os.set_blocking(self.rep_r, False)
        output.reset(keep_tail=True)
        threading.Thread(target=self._drain, args=(out_r,), daemon=True).start()

    @staticmethod
    def _stage(work: Path, source: Path) -> Path:
        """Copy the student's module into ``work/submission`` (readable by the sandbox's user)."""
        module_dir = work / "submission"
        module_dir.mkdir(parents=True)
        os.chmod(work, 0o755)
        os.chmod(module_dir, 0o755)
        shutil.copyfile(source, module_dir / source.name)
        os.chmod(module_dir / source.name, 0o644)
        return module_dir

    def _command(self, exercise: Exercise, work: Path, module_dir: Path, disk_mb: int,
                 tag: str) -> tuple[list[str], dict, list[int], dict]:
        """(argv, environment for Popen, fds to pass, other Popen arguments) for this mode."""
        argv = [worker_python(), "-I", "-c", _WORKER_CODE.format(root=str(PACKAGE_DIR.parent))]
        env = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8", "MPLBACKEND": "Agg", "OMP_NUM_THREADS": "1",
               "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "PYTHONDONTWRITEBYTECODE": "1",
               "COURSEKIT_WORKER": tag or "1"}
        if os.environ.get("COURSEKIT_FAST"):
            env["COURSEKIT_FAST"] = os.environ["COURSEKIT_FAST"]
        if self.mode != "bwrap":
            home, tmp = work / "home", work / "tmp"
            home.mkdir()
            tmp.mkdir()
            env.update(HOME=str(home), TMPDIR=str(tmp), MPLCONFIGDIR=str(home))
            return argv, env, [], {"cwd": str(home)}
        env.update(HOME="/tmp/home", TMPDIR="/tmp", MPLCONFIGDIR="/tmp/home")
        cmd, fds = bwrap_command(shutil.which("bwrap"), module_dir, disk_mb, _blanked_reference(exercise), argv, env)
        return cmd, {}, fds, _user_kwargs(sandbox_uid())  # bwrap's own environment: --clearenv, --setenv

    def _drain(self, fd: int) -> None:
        """Keep what the worker prints (a thread); stop the worker once it printed too much."""
        try:
            while True:
                chunk = os.read(fd, 65536)
                if not chunk:
                    return
                if not self.output.add(chunk):
                    self.over_output = True
                    kill_process(self.proc)
        except OSError:
            return
        finally:
            os.close(fd)

    def usage(self) -> tuple[float, int]:
        """(resident MiB, process count) of its whole tree."""
        return tree_usage(self.proc.pid)

    def ended(self) -> str:
        """How it ended: "exited with code 3", "was killed by signal SIGKILL" (waits for it)."""
        code = self.proc.wait()
        if code >= 0:
            return f"exited with code {code}"
        try:
            return f"was killed by signal {signal.Signals(-code).name}"
        except ValueError:  # a number without a name here
            return f"was killed by signal {-code}"

    def kill(self) -> None:
        kill_process(self.proc)
        for fd in (self.req_w, self.rep_r):
            try:
                os.close(fd)
            except OSError:
                pass


def _blanked_reference(exercise: Exercise) -> list[tuple[int, str]]:
    """[(memfd, path)]: the exercise's library file with its reference replaced by a raise, to mount
    over the original (empty when it cannot be made: the worker's in-memory replacement still applies)."""
    try:
        path, text = blank_reference(exercise)
        fd = os.memfd_create("reference", 0)
        os.write(fd, text.encode())
        os.lseek(fd, 0, os.SEEK_SET)
    except (OSError, ValueError, AttributeError):
        return []
    return [(fd, str(path))]
