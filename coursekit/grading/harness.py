"""The child side of a grading run: pytest on the graded tests, results over a private pipe.

Started by :mod:`coursekit.grading.runner` as ``python -I`` running :func:`main` in a scratch
folder. The parent writes one JSON line on stdin with the settings and a random nonce;
this process then applies its resource limits, closes stdin and runs pytest. Each test's
outcome is written as a JSON line carrying the nonce to a pipe file descriptor that only the
parent reads. Text the student's code prints goes to pytest's capture or to a log file that
the parent never parses, so printing or writing "PASSED" forges nothing.

Before the first test runs (and so before the student's module is imported by the ``student``
fixture) the globals of the test modules and conftest, builtins and the assertion helpers are
snapshotted; after every test they are compared and any replaced or deleted entry is reported
as tampering. This is a tripwire against casual tampering, not a sandbox: code running in this
interpreter can in principle do anything this process can (see the README, "Grading").
"""

from __future__ import annotations

import json
import os
import sys
from typing import Any

MAX_TEXT = 2000
"""Characters of traceback / captured output kept per test (the tail)."""


def _tail(text: str, limit: int = MAX_TEXT) -> str:
    return text if len(text) <= limit else "...\n" + text[-limit:]


def _first_line(text: str, limit: int = 200) -> str:
    """The first few non-empty lines joined into one (numpy's messages start with a bare "AssertionError:")."""
    line = " ".join(ln.strip() for ln in text.strip().splitlines() if ln.strip())
    return line if len(line) <= limit else line[:limit] + "..."


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
            except OSError:  # parent gone or fd closed by student code: nothing more to report
                return
            view = view[written:]


class _FunctionParts:
    """Live mapping view of the parts of a function that patching would replace."""

    _PARTS = ("__code__", "__defaults__", "__kwdefaults__", "__wrapped__")

    def __init__(self, function) -> None:
        self._function = function

    def items(self):
        return [(k, getattr(self._function, k)) for k in self._PARTS if hasattr(self._function, k)]

    def __contains__(self, key: str) -> bool:
        return hasattr(self._function, key)

    def __getitem__(self, key: str):
        return getattr(self._function, key)


def _snapshot(namespaces: dict[str, dict]) -> dict[str, dict[str, object]]:
    """The objects themselves, not their ids: holding them keeps a replaced object's address
    from being reused by its replacement (which would hide the swap)."""
    return {name: dict(ns.items()) for name, ns in namespaces.items()}


class ReportPlugin:
    """pytest plugin: streams one result per test and checks the tripwire after each."""

    def __init__(self, channel: _Channel) -> None:
        self.channel = channel
        self.phases: dict[str, dict[str, Any]] = {}
        self.namespaces: dict[str, dict] = {}
        self.snapshot: dict[str, dict[str, object]] = {}
        self.tampered = ""
        self.names: dict[str, str] = {}
        self.errors: dict[tuple[str, str], str] = {}

    # -- collection: the test functions exist before any student code runs
    def pytest_collection_finish(self, session) -> None:
        import builtins

        for item in session.items:
            module = getattr(item, "module", None)
            if module is not None:
                self.namespaces[f"test module {module.__name__}"] = module.__dict__
        for name, module in list(sys.modules.items()):
            if name.endswith("conftest") and module is not None:
                self.namespaces[f"conftest {name}"] = module.__dict__
        self.namespaces["builtins"] = builtins.__dict__
        for name in ("numpy.testing", "torch.testing"):
            if name in sys.modules:
                self.namespaces[name] = sys.modules[name].__dict__
        self.namespaces["grading plugin"] = type(self).__dict__
        # one level deeper for what the tests call: the code of their functions (a reference
        # implementation imported by name) and the attributes of classes they use
        for label, ns in list(self.namespaces.items()):
            if not label.startswith(("test module", "conftest")):
                continue
            for key, value in list(ns.items()):
                if isinstance(value, type):
                    self.namespaces[f"{label}.{key}"] = value.__dict__
                elif callable(value) and hasattr(value, "__code__"):
                    self.namespaces[f"{label}.{key}"] = _FunctionParts(value)
        self.snapshot = _snapshot(self.namespaces)
        # "<file>::<test>[<params>]": stable whatever pytest's rootdir makes of the node ids
        self.names = {item.nodeid: f"{item.path.name}::{item.name}" for item in session.items}
        self.channel.send(event="collected", tests=list(self.names.values()))

    def _check_tripwire(self) -> str:
        if self.tampered:
            return self.tampered
        for name, objects in self.snapshot.items():
            ns = self.namespaces[name]
            for key, value in objects.items():
                if key not in ns or ns[key] is not value:
                    self.tampered = f"{name}: {key!r} was replaced or deleted while the tests ran"
                    return self.tampered
        return ""

    def pytest_runtest_makereport(self, item, call) -> None:
        """Remember "ExceptionType: message" of a failing phase (returns None: pytest builds the report)."""
        if call.excinfo is not None:
            exc = call.excinfo.value
            self.errors[(item.nodeid, call.when)] = f"{type(exc).__name__}: {exc}"

    def pytest_runtest_logstart(self, nodeid, location) -> None:
        self.channel.send(event="start", test=self.names.get(nodeid, nodeid))

    def pytest_runtest_logreport(self, report) -> None:
        state = self.phases.setdefault(report.nodeid, {"outcome": "passed", "message": "", "detail": "", "output": ""})
        if report.failed or report.skipped:
            if state["outcome"] == "passed":
                state["outcome"] = "failed" if report.failed else "skipped"
                crash = getattr(report.longrepr, "reprcrash", None)
                text = str(report.longrepr) if report.longrepr is not None else ""
                if report.skipped and isinstance(report.longrepr, tuple):
                    text = str(report.longrepr[2])
                message = self.errors.get((report.nodeid, report.when)) or (crash.message if crash is not None else text)
                if report.when == "setup":
                    message = f"could not set up the test: {_first_line(message)}"
                state["message"] = _first_line(message)
                state["detail"] = _tail(text)
        output = (report.capstdout or "") + (report.capstderr or "")
        if output:
            state["output"] = _tail(state["output"] + output)
        if report.when == "teardown":
            tampered = self._check_tripwire()
            self.channel.send(event="result", test=self.names.get(report.nodeid, report.nodeid), tampered=tampered, **state)


def _apply_limits(memory_mb: int, file_mb: int) -> None:
    """Caps for this process and its children: address space, file size, no core dumps.

    A platform that refuses a limit (macOS does not enforce RLIMIT_AS) keeps going: the parent
    still polls the memory of the whole process tree and enforces the wall clock.
    """
    try:
        import resource
    except ImportError:  # not a POSIX system
        return
    limits = [(resource.RLIMIT_CORE, 0)]
    if memory_mb > 0:
        limits.append((resource.RLIMIT_AS, memory_mb * 1024 * 1024))
    if file_mb > 0:  # Python ignores SIGXFSZ, so oversized writes raise OSError (EFBIG)
        limits.append((resource.RLIMIT_FSIZE, file_mb * 1024 * 1024))
    for which, value in limits:
        try:
            resource.setrlimit(which, (value, value))
        except (ValueError, OSError):
            pass


def main() -> int:
    settings = json.loads(sys.stdin.readline())
    devnull = os.open(os.devnull, os.O_RDONLY)  # stdin is done with: nothing more to read there
    os.dup2(devnull, 0)
    os.close(devnull)
    channel = _Channel(int(settings.pop("result_fd")), settings.pop("nonce"))
    _apply_limits(int(settings["memory_mb"]), int(settings["file_mb"]))
    sys.dont_write_bytecode = True

    import pytest  # after the limits: everything from here on runs under them

    args = [
        *settings["test_files"],
        "-q", "-p", "no:cacheprovider", "-p", "pytest_timeout",
        "--rootdir", os.getcwd(), "-c", settings["ini"],
        f"--timeout={settings['test_timeout']}", "--timeout-method=signal",
        "--tb=short", "--show-capture=no", "-o", "console_output_style=classic",
    ]
    try:
        code = pytest.main(args, plugins=[ReportPlugin(channel)])
    except BaseException as exc:  # noqa: BLE001 - report anything, the parent decides
        channel.send(event="crash", message=f"{type(exc).__name__}: {exc}")
        return 3
    channel.send(event="done", exit_code=int(code))
    return 0


if __name__ == "__main__":
    sys.exit(main())
