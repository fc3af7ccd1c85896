"""The sandbox: one exercise's untrusted worker as the graded tests use it, with limits and deadlines.

The graded tests (tests/exercises/) run in the trusted test process (:mod:`coursekit.grading.trusted`)
and never import the student's module. They get two fixtures instead:

- ``student``: a :class:`RemoteModule`. ``student.q_sample(x0, t, noise, abar)`` sends the
  arguments as plain data (:mod:`coursekit.grading.codec`) to the worker
  (:mod:`coursekit.grading.worker`), which calls the student's function and sends the result
  back as plain data (arrays, tensors as plain tensors, numbers, strings, lists, dicts). A result
  that is not plain data (a FiLM layer, an executor, a bound method) stays in the worker and
  comes back as a :class:`RemoteObject` handle: call it, read its attributes, pass it back in.
  A plain function of the test passed as an argument (a recording predictor, the reference
  ``q_sample``) stays here: the worker calls back for it.
- ``sandbox``: the :class:`Sandbox` behind it, for what modules need: ``seed``, ``new`` (build a
  coursekit object in the worker, e.g. a U-Net around the student's FiLM), ``parameters``,
  ``state_dict``, ``load_state_dict`` and ``grad`` (gradients computed in the worker, returned as
  tensors).

Every call has a deadline (the per-test timeout, within the exercise's wall-clock budget); a
worker that misses it, dies, prints too much or uses too much memory is killed and the call
raises :class:`StudentCodeError` with the reason; the next call starts a fresh worker (inside
bubblewrap where it works: :mod:`coursekit.grading.bubblewrap`).
"""

from __future__ import annotations

import os
import select
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from coursekit.grading import bubblewrap, codec
from coursekit.grading.bubblewrap import PrintedOutput, WorkerProcess, become_subreaper, kill_orphans
from coursekit.grading.exercises import get_exercise

MAX_PROCESSES = 64
"""A worker tree with more processes than this is stopped (polled; RLIMIT_NPROC also applies where it binds)."""


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


class StudentCodeError(AssertionError):
    """The student's code raised, or the worker running it failed; ``cause`` says which.

    ``cause``: "error" (an exception, ``kind`` is its type), "import" (the module failed to import),
    "timeout", "crashed" (the process ended), "memory", "output" (printed too much),
    "reference" (called the reference implementation / imported solutions), "protocol".
    """

    def __init__(self, cause: str, kind: str, message: str, traceback: str = "") -> None:
        super().__init__(message)
        self.cause, self.kind, self.message, self.traceback = cause, kind, message, traceback

    @property
    def report(self) -> str:
        """One line: "ValueError: bad shape", "Timeout (>1s): ...", "calls the reference implementation (...)"."""
        return f"{self.kind}: {self.message}" if self.kind else self.message


class RemoteObject:
    """A handle to an object living in the worker: call it, read attributes, pass it back in."""

    # underscored: every other attribute name is the worker object's
    def __init__(self, box: Sandbox, generation: int, oid: int, type_name: str) -> None:
        object.__setattr__(self, "_box", box)
        object.__setattr__(self, "_gen", generation)
        object.__setattr__(self, "_id", oid)
        object.__setattr__(self, "type_name", type_name)

    def __call__(self, *args, **kwargs):
        return self._box.request("call", target=self, args=list(args), kwargs=kwargs)

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        return self._box.request("getattr", target=self, name=name)

    def __setattr__(self, name, value):
        raise AttributeError("objects in the worker are read-only from the tests (use sandbox.load_state_dict)")

    def __repr__(self) -> str:
        return f"<remote {self.type_name} #{self._id}>"


class RemoteAttr:
    """A name in the student's module (resolved in the worker each time it is used)."""

    def __init__(self, box: Sandbox, name: str) -> None:
        self._box, self.name = box, name

    def __call__(self, *args, **kwargs):
        return self._box.request("call", target=self, args=list(args), kwargs=kwargs)

    def __repr__(self) -> str:
        return f"<student's {self.name}>"


class RemoteModule:
    """The student's module as the tests see it: ``student.<name>(...)`` runs in the worker."""

    def __init__(self, box: Sandbox) -> None:
        self._box = box

    def __getattr__(self, name: str) -> RemoteAttr:
        if name.startswith("_"):
            raise AttributeError(name)
        return RemoteAttr(self._box, name)


class Sandbox:
    """One exercise's worker for one submission (restarted after a crash), with deadlines."""

    def __init__(self, exercise_id: str, folder: str | os.PathLike, scratch: str | os.PathLike, limits: Limits, *,
                 mode: str | None = None, solutions_dir: str = "", tag: str = "", reap: bool = False,
                 preload: tuple[str, ...] = ()) -> None:
        self.exercise = get_exercise(exercise_id)
        self.preload = tuple(preload)
        """Modules the worker imports at boot (:data:`coursekit.grading.worker.PRELOADABLE`), e.g.
        ("torch",) when the tests send tensors."""
        self.folder, self.scratch, self.limits = Path(folder), Path(scratch), limits
        self.mode = mode or bubblewrap.mode()
        self.solutions_dir, self.tag, self.reap = solutions_dir, tag, reap
        self.budget_end = time.monotonic() + limits.timeout_s
        self.deadline = self.budget_end
        self.test_left = limits.test_timeout_s
        """Seconds of the current test's timeout not yet spent WAITING on the worker (the test's own
        work, e.g. importing diffusers or computing a reference, does not count)."""
        self.worker: WorkerProcess | None = None
        self.launched = False
        """The current worker has its settings: it boots on its own from here (a starting thread may
        then give up the GIL, e.g. to an import, without delaying the worker)."""
        self.generation = 0
        self.sticky: StudentCodeError | None = None  # an import-time failure: the same for every test
        self.import_error: StudentCodeError | None = None
        self.callbacks: dict[int, Any] = {}
        self.output = PrintedOutput(int(limits.output_mb) * 1024 * 1024)
        self.next_poll = 0.0  # when the worker tree's memory and processes are next measured
        if reap:
            become_subreaper()

    # ----------------------------------------------------------------- per test
    def start_test(self) -> None:
        self.test_left = self.limits.test_timeout_s
        self.output.reset()  # the output limit is per test

    def output_tail(self) -> str:
        return self.output.tail()

    # ----------------------------------------------------------------- operations for tests
    def seed(self, seed: int) -> None:
        self.request("seed", seed=int(seed))

    def new(self, factory: str, *args, **kwargs):
        """Build ``factory`` ("coursekit.module:Name") in the worker, e.g. a U-Net around the student's FiLM."""
        return self.request("new", factory=factory, args=list(args), kwargs=kwargs)

    def parameters(self, obj: RemoteObject) -> dict:
        """``dict(obj.named_parameters())`` as tensors."""
        return self.request("params", target=obj)

    def state_dict(self, obj: RemoteObject) -> dict:
        return self.request("state", target=obj)

    def load_state_dict(self, obj: RemoteObject, state: dict) -> None:
        self.request("load", target=obj, state=dict(state))

    def grad(self, fn, *args, wrt=(), grad_output=None, **kwargs):
        """(output, grads): gradients of ``fn(*args, **kwargs)`` computed in the worker.

        ``wrt`` entries: an int (that positional argument; its gradient tensor, or None when none
        reached it) or a RemoteObject (a dict name -> gradient over its named parameters).
        ``grad_output`` seeds a non-scalar output (default: the output must be a scalar).
        """
        return self.request("grad", target=fn, args=list(args), kwargs=kwargs, wrt=list(wrt), grad_output=grad_output)

    # ----------------------------------------------------------------- requests
    def request(self, op: str, **fields) -> Any:
        """Send one request and serve callbacks until its reply; the reply's value (or StudentCodeError)."""
        waiting = False
        try:
            if self.worker is None or self.worker.proc.poll() is not None:
                self._start()
            if self.import_error is not None:
                raise self.import_error
            # starting the worker (torch's import on a busy machine) does not count against the test
            self.deadline = min(time.monotonic() + max(self.test_left, 0.0), self.budget_end)
            waiting = True
            self._send({"op": op, **fields})
            while True:
                reply = self._receive(self.deadline)
                if reply.get("kind") != "callback":
                    return self._value(reply)
                started = time.monotonic()
                self._callback(reply)
                self.deadline = min(self.deadline + time.monotonic() - started, self.budget_end)  # the test's time
        finally:
            if waiting:
                self.test_left = self.deadline - time.monotonic()

    def _value(self, reply: dict) -> Any:
        """The value of a result; StudentCodeError for an error or anything unexpected."""
        kind = reply.get("kind")
        if kind == "result" and not reply.get("reference"):
            return reply.get("value")
        if kind in ("result", "error"):
            raise self._error(reply)
        self.kill()
        raise StudentCodeError("protocol", "", f"unexpected message from the worker: {str(reply)[:200]}")

    def _callback(self, reply: dict) -> None:
        fn = self.callbacks.get(reply.get("id"))
        try:
            if fn is None:
                raise KeyError(f"no callback {reply.get('id')!r}")
            value = fn(*reply.get("args", []), **reply.get("kwargs", {}))
        except Exception as exc:  # noqa: BLE001 - reported to the student's code as an error
            self._send({"op": "cb_error", "message": f"{type(exc).__name__}: {exc}"})
        else:
            self._send({"op": "cb_result", "value": value})

    def _error(self, reply: dict, cause: str = "error") -> StudentCodeError:
        if reply.get("reference"):
            return StudentCodeError("reference", "", f"calls the reference implementation ({reply['reference']})",
                                    str(reply.get("traceback", "")))
        return StudentCodeError(cause, str(reply.get("type", "Error")), str(reply.get("message", "")),
                                str(reply.get("traceback", "")))

    # ----------------------------------------------------------------- the worker process
    def prestart(self) -> None:
        """Start the worker now (e.g. in a thread while the tests import torch), so that the first
        request finds it ready; a failure is left to that request, which starts it again or raises."""
        try:
            if self.worker is None:
                self._start()
        except StudentCodeError:
            pass

    def _start(self) -> None:
        if self.sticky is not None:
            raise self.sticky
        self._raise_if_spent()
        self.kill()
        self.launched = False
        self.generation += 1
        self.worker = WorkerProcess(self.exercise, self.scratch / f"worker-{self.generation}",
                                    self.folder / f"{self.exercise.id}.py", mode=self.mode,
                                    disk_mb=self.limits.disk_mb, output=self.output, tag=self.tag)
        self._send({"reply_fd": self.worker.reply_fd, "exercise": self.exercise.id, "folder": self.worker.folder,
                    "source": self.exercise.source, "objects": list(self.exercise.objects),
                    "solutions_dir": self.solutions_dir, "memory_mb": self.limits.memory_mb,
                    "file_mb": self.limits.output_mb, "disk_mb": self.limits.disk_mb,
                    "cpu_s": int(self.limits.timeout_s) + 5, "nproc": 32 if self.worker.own_user else 0,
                    "preload": list(self.preload)})
        self.launched = True
        boot = self._receive(max(self.budget_end, time.monotonic() + 1), during="starting the worker")
        if boot.get("kind") != "booted" or boot.get("error"):
            raise StudentCodeError("crashed", "", f"the worker could not start: {boot.get('error', boot)}")
        end = min(time.monotonic() + self.limits.test_timeout_s, self.budget_end)
        try:
            ready = self._receive(end, during="importing your module")
        except StudentCodeError as exc:
            self.sticky = exc
            raise
        if ready.get("kind") == "import_error":
            self.import_error = self._error(ready, "import")
        elif ready.get("kind") != "ready":
            raise StudentCodeError("protocol", "", f"unexpected message from the worker: {str(ready)[:200]}")

    def _raise_if_spent(self) -> None:
        if time.monotonic() >= self.budget_end:
            raise StudentCodeError("timeout", "", f"the tests of this exercise took longer than {self.limits.timeout_s:g} s "
                                   "in all and were stopped (an endless loop?)")

    def kill(self) -> None:
        if self.worker is not None:
            self.worker.kill()
            self.worker = None
        if self.reap:
            kill_orphans()

    def close(self) -> None:
        self.kill()

    # ----------------------------------------------------------------- messages
    def _ref(self, value: Any) -> dict:
        if isinstance(value, RemoteObject):
            if value._gen != self.generation:
                raise StudentCodeError("crashed", "", "an object made before the worker restarted was used again")
            return {"t": "obj", "id": value._id}
        if isinstance(value, RemoteAttr):
            return {"t": "attr", "name": value.name}
        if callable(value):
            key = len(self.callbacks) + 1
            self.callbacks[key] = value
            return {"t": "cb", "id": key}
        raise codec.ProtocolError(f"a {type(value).__name__} cannot be sent to the worker")

    def _send(self, message: dict) -> None:
        frame = codec.encode(message, cb_ref=self._ref)
        try:
            codec.write_frame(self.worker.req_w, frame)
        except OSError:
            pass  # the worker is gone: the next read reports how it ended

    def _receive(self, deadline: float, during: str = "running your code") -> dict:
        try:
            n = codec.frame_length(self._read(8, deadline, during))
        except codec.ProtocolError as exc:
            self.kill()
            raise StudentCodeError("protocol", "", f"the worker sent {exc}") from None
        payload = self._read(n, deadline, during)
        gen = self.generation
        try:
            return codec.decode(payload, obj=lambda v: RemoteObject(self, gen, v["id"], str(v.get("type", "?"))))
        except codec.ProtocolError as exc:
            self.kill()
            raise StudentCodeError("protocol", "", f"the worker sent a malformed reply: {exc}") from None

    def _read(self, n: int, deadline: float, during: str) -> bytes:
        parts, got = [], 0
        while got < n:
            now = time.monotonic()
            if now >= deadline:
                self.kill()
                if deadline >= self.budget_end:
                    self._raise_if_spent()
                raise StudentCodeError("timeout", "", f"Timeout (>{self.limits.test_timeout_s:g}s) while {during}: your "
                                       "code did not return in time (an endless loop?)")
            if now >= self.next_poll:  # at most every 0.5 s, not per message: psutil scans all of /proc
                self.next_poll = now + 0.5
                self._check_usage()
            ready, _, _ = select.select([self.worker.rep_r], [], [], min(0.1, max(deadline - now, 0.001)))
            if not ready:
                continue
            try:
                chunk = os.read(self.worker.rep_r, min(n - got, 1 << 20))
            except BlockingIOError:
                continue
            if not chunk:
                raise self._ended(during)
            parts.append(chunk)
            got += len(chunk)
        return b"".join(parts)

    def _check_usage(self) -> None:
        """Stop a worker tree that uses too much memory or runs too many processes."""
        rss_mb, n_procs = self.worker.usage()
        if rss_mb > 1.5 * self.limits.memory_mb:
            self.kill()
            raise StudentCodeError("memory", "", f"used more than {1.5 * self.limits.memory_mb:g} MiB of memory "
                                   "and was stopped")
        if n_procs > MAX_PROCESSES:
            self.kill()
            raise StudentCodeError("crashed", "", f"started more than {MAX_PROCESSES} processes and was stopped")

    def _ended(self, during: str) -> StudentCodeError:
        worker = self.worker
        how = worker.ended()
        self.kill()
        if worker.over_output:
            return StudentCodeError("output", "", f"printed more than the {self.limits.output_mb} MiB output limit "
                                    "and was stopped")
        return StudentCodeError("crashed", "", f"the process running your code {how} while {during} "
                                "(os._exit / sys.exit at import / a crash?)")
