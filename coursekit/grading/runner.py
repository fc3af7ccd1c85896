"""The parent side of a grading run: one sandboxed pytest subprocess, outcomes per graded test.

``run_tests`` copies the student's modules and the graded test files into a fresh scratch
folder, starts :mod:`coursekit.grading.harness` there in its own session with a memory cap, a
file-size cap, a per-test timeout and a wall-clock timeout, and reads per-test outcomes from a
private pipe, accepting only lines that carry this run's random nonce. Whatever the child does
(exits, hangs, allocates, prints, deletes files) the parent turns it into outcomes with a
reason; the whole process group is killed and the scratch folder removed at the end.
``score_exercise`` turns outcomes into points with the registry's hints.
"""

from __future__ import annotations

import hmac
import json
import os
import re
import secrets
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from coursekit.grading.child import _child_env, _kill_group, _pump, _tree_rss_mb
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
    """Resource limits of one grading subprocess."""

    timeout_s: float = 120.0
    """Wall-clock limit for the whole run (all tests of the exercise), in seconds."""
    test_timeout_s: float = 10.0
    """Per-test limit (pytest-timeout, SIGALRM): a looping test fails, the others still run."""
    memory_mb: int = 2048
    """Address-space cap (RLIMIT_AS) in MiB. Measured: every solution, torch ones included, passes
    at 768 (with one OpenMP thread); 2048 leaves room for clumsy but honest code."""
    output_mb: int = 32
    """Largest file the child may write (RLIMIT_FSIZE) in MiB: caps printed output too."""

    def __post_init__(self) -> None:
        if not self.timeout_s > 0 or not self.test_timeout_s > 0:
            raise ValueError(f"timeouts must be positive, got timeout_s={self.timeout_s!r}, test_timeout_s={self.test_timeout_s!r}")
        if int(self.memory_mb) < 256:
            raise ValueError(f"memory_mb must be at least 256 (Python + numpy need it), got {self.memory_mb!r}")
        if int(self.output_mb) < 1:
            raise ValueError(f"output_mb must be at least 1, got {self.output_mb!r}")


@dataclass
class Outcome:
    """What happened to one collected test (one pytest node, parameters included)."""

    nodeid: str
    outcome: str
    """"passed", "failed", "skipped" or "not run"."""
    message: str = ""
    """One line: the assertion or exception, or why the test never finished."""
    detail: str = ""
    """Tail of the short traceback."""
    output: str = ""
    """Tail of what the test printed."""

    @property
    def file(self) -> str:
        return self.nodeid.split("::")[0].rsplit("/", 1)[-1]

    @property
    def function(self) -> str:
        return self.nodeid.split("::")[-1].split("[")[0]


@dataclass
class RunResult:
    """Outcomes of one subprocess run and how the process ended."""

    outcomes: list[Outcome] = field(default_factory=list)
    status: str = "ok"
    """"ok", "timeout", "memory", "crashed", "tampered" or "error" (nothing could be collected)."""
    reason: str = ""
    """Human-readable explanation when status is not "ok"."""
    seconds: float = 0.0
    log_tail: str = ""
    """Last lines of the child's own stdout/stderr (pytest's summary or a traceback), for debugging."""


def read_test_sources(exercises: list[Exercise], root: Path | None = None) -> dict[str, bytes]:
    """The graded test files (and their conftest) as bytes, read once so that later edits of the
    files on disk (by a hostile submission, say) cannot change what the next run uses."""
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


MAX_ATTEMPTS = 10
"""Subprocesses per run at most: after a crash or a timeout the tests not yet run get a fresh one."""


def run_tests(exercises: list[Exercise], submission: str | os.PathLike, limits: Limits | None = None,
              sources: dict[str, bytes] | None = None) -> RunResult:
    """Run the graded tests of ``exercises`` against the modules in folder ``submission``.

    ``sources`` are the test files from :func:`read_test_sources` (read now if omitted).
    Never raises for anything the student's code does; the returned outcomes cover every
    test that was collected, each with a reason when it did not pass. When the subprocess dies
    or hangs in one test (os._exit, a loop that ignores the per-test timeout, the memory cap),
    that test fails and the tests it kept from running get a fresh subprocess, within the one
    wall-clock budget ``limits.timeout_s``, so one broken function does not zero the others.
    """
    limits = limits or Limits()
    sources = sources if sources is not None else read_test_sources(exercises)
    start = time.monotonic()
    deadline = start + limits.timeout_s
    merged = _attempt(exercises, Path(submission), limits, sources, deadline, None)
    attempts = 1
    while merged.status in ("crashed", "timeout", "memory") and attempts < MAX_ATTEMPTS:
        remaining = [o.nodeid for o in merged.outcomes if o.outcome == "not run"]
        if not remaining or time.monotonic() >= deadline:
            break
        again = _attempt(exercises, Path(submission), limits, sources, deadline, remaining)
        attempts += 1
        redone = {o.nodeid: o for o in again.outcomes}
        merged.outcomes = [redone.get(o.nodeid, o) for o in merged.outcomes]
        merged.log_tail = again.log_tail
        if again.status == "tampered":
            merged.status, merged.reason = again.status, again.reason
        if again.status in ("ok", "tampered", "error"):
            break
        # crashed again: the first failure's status and reason stay as the run's explanation
    merged.seconds = time.monotonic() - start
    return merged


def _attempt(exercises: list[Exercise], submission: Path, limits: Limits, sources: dict[str, bytes],
             deadline: float, selection: list[str] | None) -> RunResult:
    """One subprocess in a fresh scratch folder; ``selection``: "<file>::<test>" ids to run (None: all)."""
    start = time.monotonic()
    scratch = Path(tempfile.mkdtemp(prefix="coursekit-grade-"))
    result = RunResult()
    read_fd = write_fd = -1
    proc = None
    try:
        student_dir = scratch / "submission"
        _copy_submission(exercises, submission, student_dir)
        tests_dir = scratch / "tests"
        tests_dir.mkdir()
        for name, data in sources.items():
            (tests_dir / name).write_bytes(data)
        (scratch / "pytest.ini").write_text("[pytest]\n")
        (scratch / "work").mkdir()
        (scratch / "tmp").mkdir()
        if selection is None:
            test_files = [str(tests_dir / f"test_{e.id}.py") for e in exercises]
        else:
            test_files = [str(tests_dir / test_id) for test_id in selection]

        nonce = secrets.token_hex(16)
        read_fd, write_fd = os.pipe()
        os.set_blocking(read_fd, False)
        settings = {
            "nonce": nonce, "result_fd": write_fd, "test_files": test_files, "ini": str(scratch / "pytest.ini"),
            "memory_mb": int(limits.memory_mb), "file_mb": int(limits.output_mb),
            "test_timeout": float(limits.test_timeout_s),
        }
        with open(scratch / "harness.log", "wb") as log:
            proc = subprocess.Popen(
                [sys.executable, "-I", "-c", _CHILD_CODE.format(root=str(_PACKAGE_ROOT))],
                stdin=subprocess.PIPE, stdout=log, stderr=subprocess.STDOUT, cwd=scratch / "work",
                env=_child_env(scratch, student_dir), pass_fds=(write_fd,), close_fds=True,
                start_new_session=True,
            )
        os.close(write_fd)
        write_fd = -1
        try:
            proc.stdin.write((json.dumps(settings) + "\n").encode())
            proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass

        buffer, received = bytearray(), [0]
        next_rss = 0.0
        eof = False
        while True:
            if eof:  # the child closed its end (or student code did): just wait for it to finish
                time.sleep(0.05)
            else:
                ready, _, _ = select.select([read_fd], [], [], 0.05)
                if ready:
                    eof = not _pump(read_fd, buffer, received)
            if proc.poll() is not None:
                break
            now = time.monotonic()
            if now > deadline:
                result.status, result.reason = "timeout", (f"the tests took longer than {limits.timeout_s:g} s in all "
                                                           "and were stopped (an endless loop?)")
                break
            if now > next_rss:  # backstop for memory RLIMIT_AS does not see (e.g. forked children)
                next_rss = now + 0.5
                if _tree_rss_mb(proc.pid) > 1.5 * limits.memory_mb:
                    result.status, result.reason = "memory", f"used more than {1.5 * limits.memory_mb:g} MiB of memory and was stopped"
                    break
        _kill_group(proc)
        # drain what the child wrote before it ended (grandchildren were killed with the group)
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


_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def _scrub(result: RunResult, scratch: Path) -> None:
    """Strip what differs between two runs of the same code (the random scratch folder, object
    addresses in reprs) so that feedback, and a re-grade, is byte-identical."""
    prefixes = {f"{scratch}/", f"{scratch.resolve()}/"}
    for o in result.outcomes:
        texts = []
        for text in (o.message, o.detail, o.output):
            for prefix in prefixes:
                text = text.replace(prefix, "")
            texts.append(_ADDRESS.sub(" at 0x...", text))
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
    running, done, tampered, crash = None, False, "", ""
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
            text = str(message.get("message", ""))
            if "[Errno 27] File too large" in text:  # RLIMIT_FSIZE: Python ignores SIGXFSZ, writes fail
                text += f" (printed or wrote more than the {limits.output_mb} MiB output limit)"
            outcomes[test] = Outcome(test, str(message.get("outcome", "failed")), text,
                                     str(message.get("detail", "")), str(message.get("output", "")))
            tampered = tampered or str(message.get("tampered") or "")
            running = None
        elif event == "crash":
            crash = str(message.get("message", ""))
        elif event == "done":
            done = True

    if result.status == "ok" and tampered:
        result.status, result.reason = "tampered", f"tampering with the grader detected ({tampered})"
    elif result.status == "ok" and not done:
        if returncode is not None and returncode < 0:
            sig = signal.Signals(-returncode).name if -returncode in signal.Signals._value2member_map_ else -returncode
            result.status, result.reason = "crashed", f"the test process was killed by signal {sig}"
        else:
            result.status = "crashed"
            result.reason = (f"the test process exited early with code {returncode} "
                             "(os._exit / sys.exit / a crash in the code under test?)")
            if crash:
                result.reason += f": {crash}"
    if not collected and not outcomes:
        result.status = "error" if result.status == "ok" else result.status
        result.reason = result.reason or "no tests could be collected"
    for nodeid in collected:
        if nodeid in outcomes:
            continue
        if nodeid == running:
            outcomes[nodeid] = Outcome(nodeid, "failed", f"this test did not finish: {result.reason}")
        else:
            outcomes[nodeid] = Outcome(nodeid, "not run", f"not run: {result.reason}")
    order = {nodeid: i for i, nodeid in enumerate(collected)}
    result.outcomes = sorted(outcomes.values(), key=lambda o: order.get(o.nodeid, len(order)))


@dataclass
class TestScore:
    """Points for one graded test function of an exercise."""

    name: str
    points: float
    max_points: float
    passed: bool
    hint: str
    message: str = ""
    detail: str = ""
    output: str = ""


def score_exercise(exercise: Exercise, run: RunResult) -> list[TestScore]:
    """Points per registered test: max_points x (passed cases / cases); zero everywhere if the
    run was tampered with; a registered test with no outcome scores zero with the run's reason."""
    file = f"test_{exercise.id}.py"
    by_function: dict[str, list[Outcome]] = {}
    for outcome in run.outcomes:
        if outcome.file == file:
            by_function.setdefault(outcome.function, []).append(outcome)
    scores = []
    for name, (max_points, hint) in exercise.tests.items():
        cases = by_function.get(name, [])
        passed = sum(o.outcome == "passed" for o in cases)
        points = max_points * passed / len(cases) if cases else 0.0
        failed = [o for o in cases if o.outcome != "passed"]
        if run.status == "tampered":
            points, message = 0.0, run.reason
        elif not cases:
            message = run.reason or "the test was not found in the test run"
        elif failed:
            first = failed[0]
            label = f"{len(failed)}/{len(cases)} cases failed; first: " if len(cases) > 1 else ""
            message = label + (first.message or first.outcome)
        else:
            message = ""
        first_failed = failed[0] if failed else None
        scores.append(TestScore(
            name=name, points=round(points, 6), max_points=float(max_points),
            passed=bool(cases) and not failed and run.status != "tampered", hint=hint, message=message,
            detail=first_failed.detail if first_failed else "", output=first_failed.output if first_failed else "",
        ))
    return scores
