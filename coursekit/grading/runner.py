"""The parent side of a grading run: one trusted pytest process per submission, outcomes per test.

``run_tests`` copies the graded test files (and any hidden ones) into a fresh scratch folder and
starts :mod:`coursekit.grading.harness` there: pytest in a trusted process whose fixtures send
every call into student code to an untrusted worker (:mod:`coursekit.grading.remote`, sandboxed
by :mod:`coursekit.grading.sandbox`). Per-test outcomes come back over a private pipe, tagged
with a random nonce. Whatever the worker does (exits, hangs, allocates, prints, forks) costs
only the test it happened in; the wall-clock backstop here only guards against the trusted
process itself getting stuck. ``score_exercise`` turns outcomes into points with the hints.
"""

from __future__ import annotations

import ast
import hmac
import json
import os
import re
import secrets
import select
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from coursekit.grading.child import _kill_group, _pump
from coursekit.grading.paths import repo_root
from coursekit.grading.registry import Exercise

MAX_MODULE_BYTES = 2 * 1024 * 1024
"""A submitted module larger than this is not graded (nobody writes 2 MB of Python for these)."""

# The child imports the very coursekit this process runs (an editable install, a clone on
# PYTHONPATH, ...): `python -I` ignores PYTHONPATH and the current folder, so the path is explicit.
_PACKAGE_ROOT = Path(__file__).resolve().parents[2]
_CHILD_CODE = "import sys; sys.path.insert(0, {root!r}); from coursekit.grading.harness import main; sys.exit(main())"


@dataclass(frozen=True)
class Limits:
    """Resource limits of the untrusted worker that runs one exercise of one submission."""

    timeout_s: float = 120.0
    """Wall-clock budget for all tests of one exercise (worker restarts included), in seconds."""
    test_timeout_s: float = 10.0
    """Per-test limit: a call that does not return in time kills the worker; that test fails."""
    memory_mb: int = 2048
    """Address-space cap (RLIMIT_AS) in MiB. Measured: every solution, torch ones included, passes
    at 768 (with one OpenMP thread); 2048 leaves room for clumsy but honest code."""
    output_mb: int = 32
    """Most the worker may print (and largest file it may write, RLIMIT_FSIZE), in MiB."""
    disk_mb: int = 64
    """Size of the worker's private tmpfs, its only writable place (with bubblewrap), in MiB."""

    def __post_init__(self) -> None:
        if not self.timeout_s > 0 or not self.test_timeout_s > 0:
            raise ValueError(f"timeouts must be positive, got timeout_s={self.timeout_s!r}, test_timeout_s={self.test_timeout_s!r}")
        if int(self.memory_mb) < 256:
            raise ValueError(f"memory_mb must be at least 256 (Python + numpy need it), got {self.memory_mb!r}")
        if int(self.output_mb) < 1:
            raise ValueError(f"output_mb must be at least 1, got {self.output_mb!r}")
        if int(self.disk_mb) < 1:
            raise ValueError(f"disk_mb must be at least 1, got {self.disk_mb!r}")


@dataclass
class Outcome:
    """What happened to one collected test (one pytest node, parameters included)."""

    nodeid: str
    outcome: str
    """"passed", "failed", "skipped" or "not run"."""
    message: str = ""
    """One line: the assertion or exception, or why the test never finished."""
    detail: str = ""
    """Tail of the student's traceback (or the test's, for a failed comparison)."""
    output: str = ""
    """Tail of what the student's code printed during the test."""
    kind: str = ""
    """What failed: "shape", "dtype", "type", "value", "error", "timeout", "crashed", "memory", "output",
    "reference" (see :func:`coursekit.grading.harness.failure_kind`)."""
    cause: str = ""
    """Set when the worker failed rather than a comparison: the kind again (empty otherwise)."""

    @property
    def file(self) -> str:
        return self.nodeid.split("::")[0].rsplit("/", 1)[-1]

    @property
    def function(self) -> str:
        return self.nodeid.split("::")[-1].split("[")[0]


@dataclass
class RunResult:
    """Outcomes of one trusted test run and how it ended."""

    outcomes: list[Outcome] = field(default_factory=list)
    status: str = "ok"
    """"ok", "timeout", "crashed" or "error" (nothing could be collected) for the run as a whole;
    per exercise see :func:`coursekit.grading.scoring.exercise_status`."""
    reason: str = ""
    """Human-readable explanation when status is not "ok"."""
    seconds: float = 0.0
    log_tail: str = ""
    """Last lines of the trusted process's own stdout/stderr (pytest's summary), for debugging."""


def read_test_sources(exercises: list[Exercise], root: Path | None = None) -> dict[str, bytes]:
    """The graded test files (and their conftest) as bytes, read once at the start of a grading run."""
    root = Path(root) if root is not None else repo_root()
    folder = root / "tests" / "exercises"
    sources = {"conftest.py": (folder / "conftest.py").read_bytes()}
    for exercise in exercises:
        path = root / exercise.test_module
        if not path.is_file():
            raise FileNotFoundError(f"graded tests of exercise {exercise.id!r} not found at {path}")
        sources[path.name] = path.read_bytes()
    return sources


def _copy_submission(exercises: list[Exercise], submission: Path, dest: Path) -> None:
    dest.mkdir()
    for exercise in exercises:
        src = submission / f"{exercise.id}.py"
        if src.is_file() and not src.is_symlink() and src.stat().st_size <= MAX_MODULE_BYTES:
            shutil.copyfile(src, dest / src.name)


def run_tests(exercises: list[Exercise], submission: str | os.PathLike, limits: Limits | None = None,
              sources: dict[str, bytes] | None = None, hidden: dict[str, bytes] | None = None,
              mode: str | None = None, tag: str = "") -> RunResult:
    """Run the graded tests of ``exercises`` against the modules in folder ``submission``.

    ``sources``: the test files from :func:`read_test_sources` (read now if omitted); ``hidden``:
    extra instructor-only test files (name -> bytes, see :mod:`coursekit.grading.hidden`);
    ``mode``: "bwrap" or "none" (default: :func:`coursekit.grading.sandbox.mode`). Never raises
    for anything the student's code does: every collected test gets an outcome with a reason.
    """
    from coursekit.grading import sandbox

    limits = limits or Limits()
    sources = sources if sources is not None else read_test_sources(exercises)
    mode = mode or sandbox.mode()
    start = time.monotonic()
    # each exercise has its own budget inside the trusted process; this backstop only catches that
    # process itself hanging (startup of torch and pytest on a busy machine included)
    deadline = start + limits.timeout_s * max(len(exercises), 1) + 120
    scratch = Path(tempfile.mkdtemp(prefix="coursekit-grade-"))
    result = RunResult()
    read_fd = write_fd = -1
    proc = None
    try:
        student_dir = scratch / "submission"
        _copy_submission(exercises, Path(submission), student_dir)
        tests_dir = scratch / "tests"
        tests_dir.mkdir()
        for name, data in sources.items():
            (tests_dir / name).write_bytes(data)
        test_files = [str(tests_dir / f"test_{e.id}.py") for e in exercises if (student_dir / f"{e.id}.py").is_file()]
        for name, data in sorted((hidden or {}).items()):
            (tests_dir / "hidden").mkdir(exist_ok=True)
            (tests_dir / "hidden" / name).write_bytes(data)
            if _hidden_exercise(data) in {e.id for e in exercises if (student_dir / f"{e.id}.py").is_file()}:
                test_files.append(str(tests_dir / "hidden" / name))
        (scratch / "pytest.ini").write_text("[pytest]\n")
        (scratch / "work").mkdir()
        if not test_files:
            result.status, result.reason = "error", "none of the exercises' modules were found"
            return result

        nonce = secrets.token_hex(16)
        read_fd, write_fd = os.pipe()
        os.set_blocking(read_fd, False)
        settings = {
            "nonce": nonce, "result_fd": write_fd, "test_files": test_files, "ini": str(scratch / "pytest.ini"),
            "submission": str(student_dir), "memory_mb": int(limits.memory_mb), "file_mb": int(limits.output_mb),
            "disk_mb": int(limits.disk_mb), "test_timeout": float(limits.test_timeout_s),
            "budget": float(limits.timeout_s), "mode": mode, "tag": tag,
            "solutions_dir": str(repo_root() / "solutions"),
        }
        env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(scratch / "work"), "LANG": "C.UTF-8",
               "COURSEKIT_EXERCISES": str(student_dir), "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1", "MPLBACKEND": "Agg",
               "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
               "COURSEKIT_ROOT": str(repo_root())}
        if os.environ.get("COURSEKIT_FAST"):
            env["COURSEKIT_FAST"] = os.environ["COURSEKIT_FAST"]
        with open(scratch / "harness.log", "wb") as log:
            proc = subprocess.Popen(
                [sys.executable, "-I", "-c", _CHILD_CODE.format(root=str(_PACKAGE_ROOT))],
                stdin=subprocess.PIPE, stdout=log, stderr=subprocess.STDOUT, cwd=scratch / "work",
                env=env, pass_fds=(write_fd,), close_fds=True, start_new_session=True,
            )
        os.close(write_fd)
        write_fd = -1
        try:
            proc.stdin.write((json.dumps(settings) + "\n").encode())
            proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass

        buffer, received = bytearray(), [0]
        eof = False
        while True:
            if eof:
                time.sleep(0.05)
            else:
                ready, _, _ = select.select([read_fd], [], [], 0.05)
                if ready:
                    eof = not _pump(read_fd, buffer, received)
            if proc.poll() is not None:
                break
            if time.monotonic() > deadline:
                result.status, result.reason = "timeout", "the trusted test process did not finish in time and was stopped"
                break
        _kill_group(proc)
        drain_until = time.monotonic() + 1.0
        while not eof and time.monotonic() < drain_until:
            ready, _, _ = select.select([read_fd], [], [], 0.05)
            if ready:
                eof = not _pump(read_fd, buffer, received)
        _interpret(bytes(buffer), nonce, proc.returncode, limits, result)
        _scrub(result, scratch)
        result.log_tail = _log_tail(scratch / "harness.log")
    finally:
        for fd in (read_fd, write_fd):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        if proc is not None and proc.returncode is None:
            _kill_group(proc)
        shutil.rmtree(scratch, ignore_errors=True)
        result.seconds = time.monotonic() - start
    return result


def _hidden_exercise(data: bytes) -> str:
    """The EXERCISE constant of a hidden test file ("" if it has none)."""
    try:
        tree = ast.parse(data)
    except SyntaxError:
        return ""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "EXERCISE" for t in node.targets):
            try:
                return str(ast.literal_eval(node.value))
            except ValueError:
                return ""
    return ""


_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
_HANDLE = re.compile(r"#\d{6,}>")
_SUBMISSION = re.compile(r"(?<=\")[^\"\s]*/submission/")


def _scrub(result: RunResult, scratch: Path) -> None:
    """Strip what differs between two runs or names the instructor's machine (the scratch folder,
    the library's and the interpreter's absolute paths, object addresses) so that feedback is
    portable and a re-grade byte-identical."""
    from coursekit.grading import sandbox

    prefixes = [(f"{scratch}/", ""), (f"{scratch.resolve()}/", ""), (f"{_PACKAGE_ROOT}/", "")]
    prefixes += [(f"{p}/", "<python>/") for p in sandbox.python_dirs()]
    for o in result.outcomes:
        texts = []
        for text in (o.message, o.detail, o.output):
            for prefix, new in prefixes:
                text = text.replace(prefix, new)
            text = _SUBMISSION.sub("", text)  # "/submission/chunk_windows.py" -> "chunk_windows.py"
            text = _HANDLE.sub("#...>", _ADDRESS.sub(" at 0x...", text))
            texts.append(text)
        o.message, o.detail, o.output = texts


def _log_tail(path: Path, limit: int = 3000) -> str:
    try:
        with open(path, "rb") as fh:
            fh.seek(max(0, path.stat().st_size - limit))
            return fh.read().decode("utf-8", errors="replace")
    except OSError:
        return ""


def _interpret(data: bytes, nonce: str, returncode: int | None, limits: Limits, result: RunResult) -> None:
    """Turn the nonce-tagged messages and the exit status into per-test outcomes."""
    collected: list[str] = []
    outcomes: dict[str, Outcome] = {}
    running, done, crash = None, False, ""
    for line in data.decode("utf-8", errors="replace").splitlines():
        try:
            message = json.loads(line)
        except ValueError:
            continue
        if not isinstance(message, dict) or not hmac.compare_digest(str(message.get("nonce", "")), nonce):
            continue  # not from the harness: ignore (a forged or garbled line)
        event = message.get("event")
        if event == "collected" and not collected:
            collected = [str(t) for t in message.get("tests", [])]
        elif event == "start":
            running = str(message.get("test"))
        elif event == "result":
            test = str(message.get("test"))
            if test in outcomes:
                continue  # only the first report of a test counts
            outcomes[test] = Outcome(test, str(message.get("outcome", "failed")), str(message.get("message", "")),
                                     str(message.get("detail", "")), str(message.get("output", "")),
                                     str(message.get("kind", "")), str(message.get("cause", "")))
            running = None
        elif event == "crash":
            crash = str(message.get("message", ""))
        elif event == "done":
            done = True

    if result.status == "ok" and not done:
        result.status = "crashed"
        result.reason = f"the trusted test process ended early (exit code {returncode})" + (f": {crash}" if crash else "")
    if not collected and not outcomes:
        result.status = "error" if result.status == "ok" else result.status
        result.reason = result.reason or "no tests could be collected"
    for nodeid in collected:
        if nodeid in outcomes:
            continue
        if nodeid == running:
            outcomes[nodeid] = Outcome(nodeid, "failed", f"this test did not finish: {result.reason}", kind="crashed",
                                       cause="crashed")
        else:
            outcomes[nodeid] = Outcome(nodeid, "not run", f"not run: {result.reason}", kind="crashed", cause="crashed")
    order = {nodeid: i for i, nodeid in enumerate(collected)}
    result.outcomes = sorted(outcomes.values(), key=lambda o: order.get(o.nodeid, len(order)))


from coursekit.grading.scoring import TestScore, score_exercise  # noqa: E402,F401 - re-exported (older imports)
