"""The trusted test process: pytest on the graded tests, every call into student code sent to a sandbox.

Grader side, :func:`run_tests`: copies the graded test files (and any hidden ones) into a fresh
scratch folder and starts :func:`main` there as ``python -I``, one process per submission. Per-test
outcomes come back over a private pipe, tagged with a random nonce (:func:`interpret_messages`).
The wall-clock backstop here only guards against the trusted process itself getting stuck.

Process side, :func:`main`: reads its settings (one JSON line on stdin) and runs pytest on the
graded (and hidden) test files, whose ``student`` / ``sandbox`` fixtures (tests/exercises/conftest.py)
talk to one untrusted worker per exercise (:class:`coursekit.grading.sandbox.Sandbox`). The
student's code never runs in this process, so nothing it does can change a comparison, pytest, or
this reporting channel; whatever the worker does (exits, hangs, allocates, prints, forks) costs
only the test it happened in. :mod:`coursekit.grading.report` turns the outcomes into points.
"""

from __future__ import annotations

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
from typing import Any

from coursekit.grading import bubblewrap
from coursekit.grading.exercises import Exercise, read_test_sources, repo_root
from coursekit.grading.report import WORKER_CAUSES, HiddenTests, TestOutcome, failure_kind, one_line, text_tail
from coursekit.grading.sandbox import Limits

MAX_MODULE_BYTES = 2 * 1024 * 1024
"""A submitted module larger than this is not graded (nobody writes 2 MB of Python for these)."""
MAX_PIPE_BYTES = 8 * 1024 * 1024
"""The grader stops storing result messages beyond this many bytes."""

# The process imports the very coursekit the grader runs (an editable install, a clone on
# PYTHONPATH, ...): `python -I` ignores PYTHONPATH and the current folder, so the path is explicit.
_PACKAGE_ROOT = bubblewrap.PACKAGE_DIR.parent
_CHILD_CODE = "import sys; sys.path.insert(0, {root!r}); from coursekit.grading.trusted import main; sys.exit(main())"


@dataclass
class RunResult:
    """Outcomes of one trusted test run and how it ended."""

    outcomes: list[TestOutcome] = field(default_factory=list)
    """One per collected pytest node, in collection order."""
    status: str = "ok"
    """"ok", "timeout", "crashed" or "error" (nothing could be collected) for the run as a whole;
    per exercise see :func:`coursekit.grading.report.exercise_status`."""
    reason: str = ""
    """Human-readable explanation when status is not "ok"."""
    seconds: float = 0.0
    log_tail: str = ""
    """Last lines of the trusted process's own stdout/stderr (pytest's summary), for debugging."""


def run_tests(exercises: list[Exercise], submission: str | os.PathLike, limits: Limits | None = None,
              sources: dict[str, bytes] | None = None, hidden: HiddenTests | None = None,
              mode: str | None = None, tag: str = "") -> RunResult:
    """Run the graded tests of ``exercises`` against the modules in folder ``submission``.

    ``sources``: the test files from :func:`coursekit.grading.exercises.read_test_sources` (read
    now if omitted); ``hidden``: instructor-only tests (:func:`coursekit.grading.report.load_hidden_tests`);
    ``mode``: "bwrap" or "none" (default: :func:`coursekit.grading.bubblewrap.mode`). Never raises
    for anything the student's code does: every collected test gets an outcome with a reason.
    """
    limits = limits or Limits()
    sources = sources if sources is not None else read_test_sources(exercises)
    mode = mode or bubblewrap.mode()
    start = time.monotonic()
    # each exercise has its own budget inside the trusted process; this backstop only catches that
    # process itself hanging (startup of torch and pytest on a busy machine included)
    deadline = start + limits.timeout_s * max(len(exercises), 1) + 120
    scratch = Path(tempfile.mkdtemp(prefix="coursekit-grade-"))
    result = RunResult()
    try:
        settings = _stage(scratch, exercises, Path(submission), sources, hidden or HiddenTests(), limits)
        if not settings["test_files"]:
            result.status, result.reason = "error", "none of the exercises' modules were found"
            return result
        settings.update(mode=mode, tag=tag)
        nonce = secrets.token_hex(16)
        data, returncode = _run_process(scratch, settings, nonce, deadline, result)
        interpret_messages(data, nonce, returncode, result)
        _scrub(result, scratch)
        result.log_tail = _log_tail(scratch / "trusted.log")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        result.seconds = time.monotonic() - start
    return result


def _stage(scratch: Path, exercises: list[Exercise], submission: Path, sources: dict[str, bytes],
           hidden: HiddenTests, limits: Limits) -> dict[str, Any]:
    """Lay out ``scratch`` (the submission's modules, the test files, pytest.ini); the process's settings."""
    student_dir = scratch / "submission"
    student_dir.mkdir()
    for exercise in exercises:
        src = submission / f"{exercise.id}.py"
        if src.is_file() and not src.is_symlink() and src.stat().st_size <= MAX_MODULE_BYTES:
            shutil.copyfile(src, student_dir / src.name)
    tests_dir = scratch / "tests"
    tests_dir.mkdir()
    for name, data in sources.items():
        (tests_dir / name).write_bytes(data)
    present = [e.id for e in exercises if (student_dir / f"{e.id}.py").is_file()]
    test_files = [str(tests_dir / f"test_{e}.py") for e in present]
    if hidden.sources:
        (tests_dir / "hidden").mkdir()
        for name, data in sorted(hidden.sources.items()):
            (tests_dir / "hidden" / name).write_bytes(data)
        test_files += [str(tests_dir / "hidden" / name) for name in hidden.files_for(present)]
    (scratch / "pytest.ini").write_text("[pytest]\n")
    (scratch / "work").mkdir()
    return {"test_files": test_files, "ini": str(scratch / "pytest.ini"), "submission": str(student_dir),
            "memory_mb": int(limits.memory_mb), "file_mb": int(limits.output_mb), "disk_mb": int(limits.disk_mb),
            "test_timeout": float(limits.test_timeout_s), "budget": float(limits.timeout_s),
            "solutions_dir": str(repo_root() / "solutions")}


def _run_process(scratch: Path, settings: dict[str, Any], nonce: str, deadline: float,
                 result: RunResult) -> tuple[bytes, int | None]:
    """Run the trusted process in ``scratch`` until it ends or ``deadline`` passes (then ``result``'s
    status is "timeout"); (what it sent on its result pipe, its exit status)."""
    read_fd, write_fd = os.pipe()
    proc = None
    try:
        os.set_blocking(read_fd, False)
        env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(scratch / "work"), "LANG": "C.UTF-8",
               "COURSEKIT_EXERCISES": settings["submission"], "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1",
               "MPLBACKEND": "Agg", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
               "COURSEKIT_ROOT": str(repo_root())}
        if os.environ.get("COURSEKIT_FAST"):
            env["COURSEKIT_FAST"] = os.environ["COURSEKIT_FAST"]
        message = json.dumps({**settings, "nonce": nonce, "result_fd": write_fd}) + "\n"  # the same number there
        with open(scratch / "trusted.log", "wb") as log:
            proc = subprocess.Popen(
                [sys.executable, "-I", "-c", _CHILD_CODE.format(root=str(_PACKAGE_ROOT))],
                stdin=subprocess.PIPE, stdout=log, stderr=subprocess.STDOUT, cwd=scratch / "work",
                env=env, pass_fds=(write_fd,), close_fds=True, start_new_session=True,
            )
        os.close(write_fd)
        write_fd = -1
        try:
            proc.stdin.write(message.encode())
            proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass
        return _collect(proc, read_fd, deadline, result), proc.returncode
    finally:
        for fd in (read_fd, write_fd):
            if fd >= 0:
                os.close(fd)
        if proc is not None and proc.returncode is None:
            bubblewrap.kill_process(proc)


class _Inbox:
    """What arrives on the result pipe (stored up to MAX_PIPE_BYTES)."""

    def __init__(self, fd: int) -> None:
        self.fd, self.data, self.received, self.eof = fd, bytearray(), 0, False

    def pump(self, timeout: float) -> None:
        """Read what is available within ``timeout`` seconds; ``eof`` once the writers are gone."""
        ready, _, _ = select.select([self.fd], [], [], timeout)
        if not ready:
            return
        try:
            chunk = os.read(self.fd, 65536)
        except BlockingIOError:
            return
        if not chunk:
            self.eof = True
        elif self.received < MAX_PIPE_BYTES:
            self.data.extend(chunk[: MAX_PIPE_BYTES - self.received])
        self.received += len(chunk)


def _collect(proc: subprocess.Popen, read_fd: int, deadline: float, result: RunResult) -> bytes:
    """Read the result pipe until the process ends (or ``deadline``), stop its session, drain the rest."""
    inbox = _Inbox(read_fd)
    while True:
        if inbox.eof:
            time.sleep(0.05)
        else:
            inbox.pump(0.05)
        if proc.poll() is not None:
            break
        if time.monotonic() > deadline:
            result.status, result.reason = "timeout", "the trusted test process did not finish in time and was stopped"
            break
    bubblewrap.kill_process(proc)  # its workers die with it (--die-with-parent, or the session's SIGKILL)
    drain_until = time.monotonic() + 1.0
    while not inbox.eof and time.monotonic() < drain_until:
        inbox.pump(0.05)
    return bytes(inbox.data)


def interpret_messages(data: bytes, nonce: str, returncode: int | None, result: RunResult) -> None:
    """Turn the nonce-tagged messages and the exit status into ``result``'s per-test outcomes."""
    collected: list[str] = []
    outcomes: dict[str, TestOutcome] = {}
    running, done, crash = None, False, ""
    for line in data.decode("utf-8", errors="replace").splitlines():
        try:
            message = json.loads(line)
        except ValueError:
            continue
        if not isinstance(message, dict) or not hmac.compare_digest(str(message.get("nonce", "")), nonce):
            continue  # not from the trusted process: ignore (a forged or garbled line)
        event = message.get("event")
        if event == "collected" and not collected:
            collected = [str(t) for t in message.get("tests", [])]
        elif event == "start":
            running = str(message.get("test"))
        elif event == "result":
            test = str(message.get("test"))
            if test not in outcomes:  # only the first report of a test counts
                outcomes[test] = TestOutcome(test, str(message.get("outcome", "failed")), str(message.get("message", "")),
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
        if nodeid not in outcomes:
            unfinished = nodeid == running
            outcomes[nodeid] = TestOutcome(nodeid, "failed" if unfinished else "not run", kind="crashed", cause="crashed",
                                           message=(f"this test did not finish: {result.reason}" if unfinished
                                                    else f"not run: {result.reason}"))
    order = {nodeid: i for i, nodeid in enumerate(collected)}
    result.outcomes = sorted(outcomes.values(), key=lambda o: order.get(o.name, len(order)))


_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
_HANDLE = re.compile(r"#\d{6,}>")
_SUBMISSION = re.compile(r"(?<=\")[^\"\s]*/submission/")


def _scrub(result: RunResult, scratch: Path) -> None:
    """Strip what differs between two runs or names the instructor's machine (the scratch folder,
    the library's and the interpreter's absolute paths, object addresses) so that feedback is
    portable and a re-grade byte-identical."""
    prefixes = [(f"{scratch}/", ""), (f"{scratch.resolve()}/", ""), (f"{_PACKAGE_ROOT}/", "")]
    prefixes += [(f"{p}/", "<python>/") for p in bubblewrap.python_dirs()]
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


# ---------------------------------------------------------------------------------------- the process
class Channel:
    """Write-only JSON-lines channel to the grader, every message tagged with the nonce."""

    def __init__(self, fd: int, nonce: str) -> None:
        self._fd, self._nonce = fd, nonce

    def send(self, **message: Any) -> None:
        data = (json.dumps({"nonce": self._nonce, **message}, default=str) + "\n").encode()
        view = memoryview(data)
        while view:
            try:
                written = os.write(self._fd, view)
            except OSError:  # the grader is gone: nothing more to report
                return
            view = view[written:]


class ReportPlugin:
    """pytest plugin: streams one result per test; holds the settings the fixtures read."""

    def __init__(self, channel: Channel | None, settings: dict) -> None:
        self.channel = channel
        self.settings = settings
        self.phases: dict[str, dict[str, Any]] = {}
        self.names: dict[str, str] = {}
        self.errors: dict[tuple[str, str], tuple[str, str, str]] = {}

    def _send(self, **message: Any) -> None:
        if self.channel is not None:
            self.channel.send(**message)

    def pytest_collection_finish(self, session) -> None:
        self.names = {item.nodeid: f"{item.path.name}::{item.name}" for item in session.items}
        self._send(event="collected", tests=list(self.names.values()))

    def pytest_runtest_makereport(self, item, call) -> None:
        """Remember the one-line reason, failure kind and student traceback of a failing phase."""
        if call.excinfo is not None:
            exc = call.excinfo.value
            report = getattr(exc, "report", None) or f"{type(exc).__name__}: {exc}"
            # the student's own traceback when their code failed (none for a timeout or a crash: the
            # test's frames inside the grader would only be noise); the test's for a failed comparison
            student_tb = getattr(exc, "traceback", None)
            self.errors[(item.nodeid, call.when)] = (report, failure_kind(exc, report), student_tb)

    def pytest_runtest_logstart(self, nodeid, location) -> None:
        self._send(event="start", test=self.names.get(nodeid, nodeid))

    def pytest_runtest_logreport(self, report) -> None:
        state = self.phases.setdefault(report.nodeid, {"outcome": "passed", "message": "", "detail": "",
                                                       "output": "", "kind": "", "cause": ""})
        if (report.failed or report.skipped) and state["outcome"] == "passed":
            state["outcome"] = "failed" if report.failed else "skipped"
            crash = getattr(report.longrepr, "reprcrash", None)
            text = str(report.longrepr) if report.longrepr is not None else ""
            if report.skipped and isinstance(report.longrepr, tuple):
                text = str(report.longrepr[2])
            message, kind, student_tb = self.errors.get((report.nodeid, report.when)) or (
                crash.message if crash is not None else text, "value", None)
            if report.when == "setup":
                message = f"could not set up the test: {one_line(message)}"
            state["message"] = one_line(message)
            state["kind"] = kind if report.failed else ""
            state["cause"] = kind if kind in WORKER_CAUSES else ""
            # the student's own traceback when their code raised; else the test's (short) one
            state["detail"] = text_tail(text if student_tb is None else student_tb)
        for name, value in report.user_properties:
            if name == "student_output" and value:
                state["output"] = text_tail(state["output"] + value)
        if report.when == "teardown":
            self._send(event="result", test=self.names.get(report.nodeid, report.nodeid), **state)


def grading_settings(config) -> dict | None:
    """The settings of the grading run this pytest session belongs to (None outside the grader)."""
    for plugin in config.pluginmanager.get_plugins():
        if isinstance(plugin, ReportPlugin):
            return plugin.settings
    return None


def main() -> int:
    """The trusted process: settings from stdin, pytest on the test files, results to the pipe."""
    settings = json.loads(sys.stdin.readline())
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    channel = Channel(int(settings.pop("result_fd")), settings.pop("nonce"))
    sys.dont_write_bytecode = True

    import pytest

    args = [
        *settings["test_files"],
        "-q", "-p", "no:cacheprovider", "--import-mode=importlib",
        "--rootdir", os.getcwd(), "-c", settings["ini"], f"--basetemp={os.path.join(os.getcwd(), 'tmp')}",
        "--tb=short", "--show-capture=no", "-o", "console_output_style=classic",
    ]
    try:
        code = pytest.main(args, plugins=[(ReportPlugin(channel, settings))])
    except BaseException as exc:  # noqa: BLE001 - report anything, the grader decides
        channel.send(event="crash", message=f"{type(exc).__name__}: {exc}")
        return 3
    channel.send(event="done", exit_code=int(code))
    # Everything is reported and every worker closed: skip the interpreter's teardown, which with
    # torch loaded takes longer than many an exercise's tests (coursekit check answers sooner).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)
