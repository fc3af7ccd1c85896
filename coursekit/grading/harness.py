"""The trusted test process: pytest on the graded tests, each call into student code sent to a worker.

Started by :mod:`coursekit.grading.runner` as ``python -I`` running :func:`main` in a scratch
folder. The parent writes one JSON line on stdin with the settings; this process runs pytest
on the graded (and hidden) test files, whose ``student`` / ``sandbox`` fixtures
(tests/exercises/conftest.py) talk to one untrusted worker per exercise
(:mod:`coursekit.grading.remote`). The student's code never runs in this process, so nothing it
does can change a comparison, pytest, or this reporting channel. Each test's outcome goes as a
JSON line (tagged with a nonce) to a pipe only the parent reads.
"""

from __future__ import annotations

import json
import os
import re
import sys
from typing import Any

MAX_TEXT = 2000
"""Characters of traceback / captured output kept per test (the tail)."""
PLUGIN_NAME = "coursekit-grading"


def _tail(text: str, limit: int = MAX_TEXT) -> str:
    return text if len(text) <= limit else "...\n" + text[-limit:]


def _first_line(text: str, limit: int = 300) -> str:
    """The first few non-empty lines joined into one (numpy's messages start with a bare "AssertionError:")."""
    line = " ".join(ln.strip() for ln in text.strip().splitlines() if ln.strip())
    return line if len(line) <= limit else line[:limit] + "..."


_KINDS = [
    ("shape", re.compile(r"shape|size of tensor|must match the size|broadcast", re.I)),
    ("dtype", re.compile(r"dtype|data type", re.I)),
    ("type", re.compile(r"expected a .*tensor|isinstance|is not a|got <class|not an? (array|tensor|ndarray)", re.I)),
    ("value", re.compile(r"not (close|equal)|mismatch|differs|Arrays are not|!=|==|assert", re.I)),
]


def failure_kind(exc: BaseException | None, message: str) -> str:
    """What failed: a StudentCodeError's cause ("error", "timeout", ...) or, for a failed comparison,
    "shape", "dtype", "type" or "value" (from the assertion's message)."""
    cause = getattr(exc, "cause", None)
    if cause:
        return "error" if cause == "import" else cause
    if exc is not None and not isinstance(exc, AssertionError):
        return "error"
    for kind, pattern in _KINDS:
        if pattern.search(message):
            return kind
    return "value"


class _Channel:
    """Write-only JSON-lines channel to the parent, every message tagged with the nonce."""

    def __init__(self, fd: int, nonce: str) -> None:
        self._fd, self._nonce = fd, nonce

    def send(self, **message: Any) -> None:
        data = (json.dumps({"nonce": self._nonce, **message}, default=str) + "\n").encode()
        view = memoryview(data)
        while view:
            try:
                written = os.write(self._fd, view)
            except OSError:  # parent gone: nothing more to report
                return
            view = view[written:]


class ReportPlugin:
    """pytest plugin: streams one result per test; holds the settings the fixtures read."""

    def __init__(self, channel: _Channel | None, settings: dict) -> None:
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
                message = f"could not set up the test: {_first_line(message)}"
            state["message"] = _first_line(message)
            state["kind"] = kind if report.failed else ""
            state["cause"] = kind if kind in ("error", "timeout", "crashed", "memory", "output", "reference",
                                              "protocol") else ""
            # the student's own traceback when their code raised; else the test's (short) one
            state["detail"] = _tail(text if student_tb is None else student_tb)
        for name, value in report.user_properties:
            if name == "student_output" and value:
                state["output"] = _tail(state["output"] + value)
        if report.when == "teardown":
            self._send(event="result", test=self.names.get(report.nodeid, report.nodeid), **state)


def main() -> int:
    settings = json.loads(sys.stdin.readline())
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    channel = _Channel(int(settings.pop("result_fd")), settings.pop("nonce"))
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
    except BaseException as exc:  # noqa: BLE001 - report anything, the parent decides
        channel.send(event="crash", message=f"{type(exc).__name__}: {exc}")
        return 3
    channel.send(event="done", exit_code=int(code))
    # Everything is reported and every worker closed: skip the interpreter's teardown, which with
    # torch loaded takes longer than many an exercise's tests (coursekit check answers sooner).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


if __name__ == "__main__":
    sys.exit(main())


def grading_settings(config) -> dict | None:
    """The settings of the grading run this pytest session belongs to (None outside the grader)."""
    for plugin in config.pluginmanager.get_plugins():
        if isinstance(plugin, ReportPlugin):
            return plugin.settings
    return None
