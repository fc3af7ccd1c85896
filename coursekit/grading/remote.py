"""The trusted side of a call into student code: a worker process, proxies, deadlines.

The graded tests (tests/exercises/) run in a trusted pytest process and never import the
student's module. They get two fixtures instead:

- ``student``: a :class:`RemoteModule`. ``student.q_sample(x0, t, noise, abar)`` sends the
  arguments as plain data to the worker, which calls the student's function and sends the result
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
raises :class:`StudentCodeError` with the reason; the next call starts a fresh worker.
"""

from __future__ import annotations

import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from coursekit.grading import protocol, sandbox
from coursekit.grading.proxy import RemoteAttr, RemoteModule, RemoteObject, StudentCodeError  # noqa: F401 - re-exported
from coursekit.grading.sandbox import become_subreaper, kill_orphans, kill_process, tree_usage
from coursekit.grading.registry import get_exercise

OUTPUT_TAIL = 4000
"""Characters of printed output kept per test."""
MAX_PROCESSES = 64
"""A worker tree with more processes than this is stopped (polled; RLIMIT_NPROC also applies where it binds)."""


class Sandbox:
    """One exercise's worker for one submission (restarted after a crash), with deadlines."""

    def __init__(self, exercise_id: str, folder: str | os.PathLike, scratch: str | os.PathLike, *,
                 test_timeout: float = 10.0, budget: float = 120.0, memory_mb: int = 2048,
                 output_mb: int = 32, disk_mb: int = 64, mode: str | None = None,
                 solutions_dir: str = "", tag: str = "", reap: bool = False) -> None:
        self.exercise = get_exercise(exercise_id)
        self.folder, self.scratch = Path(folder), Path(scratch)
        self.test_timeout, self.memory_mb, self.output_mb, self.disk_mb = test_timeout, memory_mb, output_mb, disk_mb
        self.mode = mode or sandbox.mode()
        self.solutions_dir, self.tag = solutions_dir, tag
        self.budget_end = time.monotonic() + budget
        self.budget = budget
        self.deadline = self.budget_end
        self.test_left = test_timeout
        """Seconds of the current test's timeout not yet spent WAITING on the worker (the test's own
        work, e.g. importing diffusers or computing a reference, does not count)."""
        self.proc: subprocess.Popen | None = None
        self.generation = 0
        self.sticky: StudentCodeError | None = None  # an import-time failure: the same for every test
        self.import_error: StudentCodeError | None = None
        self.callbacks: dict[int, Any] = {}
        self.output = bytearray()
        self.printed = 0
        self.output_lock = threading.Lock()
        self.starts = 0
        self.causes: list[str] = []
        self.reference = ""
        self.over_output = None
        self.next_poll = 0.0
        self.reap = reap
        if reap:
            become_subreaper()

    # ----------------------------------------------------------------- per test
    def start_test(self) -> None:
        self.test_left = self.test_timeout
        with self.output_lock:
            self.output.clear()
            self.printed = 0  # the output limit is per test

    def output_tail(self) -> str:
        with self.output_lock:
            return bytes(self.output[-OUTPUT_TAIL:]).decode("utf-8", errors="replace")

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

    # ----------------------------------------------------------------- the worker process
    def _raise_if_spent(self) -> None:
        if time.monotonic() >= self.budget_end:
            raise StudentCodeError("timeout", "", f"the tests of this exercise took longer than {self.budget:g} s in "
                                   "all and were stopped (an endless loop?)")

    def prestart(self) -> None:
        """Start the worker now (e.g. in a thread while the tests import torch), so that the first
        request finds it ready; a failure is left to that request, which starts it again or raises."""
        try:
            if self.proc is None:
                self._start()
        except StudentCodeError:
            pass

    def _start(self) -> None:
        if self.sticky is not None:
            raise self.sticky
        self._raise_if_spent()
        self.kill()
        self.starts += 1
        self.generation += 1
        work = self.scratch / f"worker-{self.generation}"
        module_dir = work / "submission"
        module_dir.mkdir(parents=True)
        os.chmod(work, 0o755)
        os.chmod(module_dir, 0o755)
        src = self.folder / f"{self.exercise.id}.py"
        shutil.copyfile(src, module_dir / src.name)
        os.chmod(module_dir / src.name, 0o644)
        req_r, req_w = os.pipe()
        rep_r, rep_w = os.pipe()
        out_r, out_w = os.pipe()
        code = (f"import sys; sys.path.insert(0, {str(sandbox.PACKAGE_DIR.parent)!r}); "
                "from coursekit.grading.worker import main; sys.exit(main())")
        argv = [sandbox.worker_python(), "-I", "-c", code]
        env = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8", "MPLBACKEND": "Agg", "OMP_NUM_THREADS": "1",
               "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "PYTHONDONTWRITEBYTECODE": "1",
               "COURSEKIT_WORKER": self.tag or "1"}
        if os.environ.get("COURSEKIT_FAST"):
            env["COURSEKIT_FAST"] = os.environ["COURSEKIT_FAST"]
        fds: list[int] = []
        kwargs: dict = {}
        if self.mode == "bwrap":
            env.update(HOME="/tmp/home", TMPDIR="/tmp", MPLCONFIGDIR="/tmp/home")
            folder = "/submission"
            blanked = []
            try:
                from coursekit.grading.build import blank_reference

                path, text = blank_reference(self.exercise)
                fd = os.memfd_create("reference", 0)
                os.write(fd, text.encode())
                os.lseek(fd, 0, os.SEEK_SET)
                blanked.append((fd, str(path)))
            except (OSError, ValueError, AttributeError):
                pass  # the in-memory replacement in the worker still applies
            cmd, fds = sandbox.bwrap_command(shutil.which("bwrap"), module_dir, self.disk_mb, blanked, argv, env)
            uid = sandbox.sandbox_uid()
            if uid is not None:
                kwargs.update(user=uid, group=uid, extra_groups=[])
            env_for_popen = {}
        else:
            home, tmp = work / "home", work / "tmp"
            home.mkdir()
            tmp.mkdir()
            env.update(HOME=str(home), TMPDIR=str(tmp), MPLCONFIGDIR=str(home))
            folder = str(module_dir)
            cmd = argv
            env_for_popen = env
            kwargs["cwd"] = str(home)
        os.set_inheritable(rep_w, True)
        try:
            self.proc = subprocess.Popen(
                cmd, stdin=req_r, stdout=out_w, stderr=out_w, pass_fds=(rep_w, *fds), env=env_for_popen,
                start_new_session=True, **kwargs)
        finally:
            for fd in (req_r, rep_w, out_w, *fds):
                os.close(fd)
        self.req_w, self.rep_r = req_w, rep_r
        os.set_blocking(rep_r, False)
        self.printed = 0
        threading.Thread(target=self._drain, args=(out_r,), daemon=True).start()
        settings = {"reply_fd": rep_w, "exercise": self.exercise.id, "folder": folder, "source": self.exercise.source,
                    "objects": list(self.exercise.objects), "solutions_dir": self.solutions_dir,
                    "memory_mb": self.memory_mb, "file_mb": self.output_mb, "disk_mb": self.disk_mb,
                    "cpu_s": int(self.budget) + 5, "nproc": 32 if self.mode == "bwrap" and kwargs.get("user") else 0}
        self._send(settings)
        boot = self._receive(max(self.budget_end, time.monotonic() + 1), during="starting the worker")
        if boot.get("kind") != "booted" or boot.get("error"):
            raise StudentCodeError("crashed", "", f"the worker could not start: {boot.get('error', boot)}")
        end = min(time.monotonic() + self.test_timeout, self.budget_end)
        try:
            ready = self._receive(end, during="importing your module")
        except StudentCodeError as exc:
            self.sticky = exc
            raise
        if ready.get("kind") == "import_error":
            self.import_error = self._error(ready, "import")
        elif ready.get("kind") != "ready":
            raise StudentCodeError("protocol", "", f"unexpected message from the worker: {str(ready)[:200]}")

    def _drain(self, fd: int) -> None:
        limit = self.output_mb * 1024 * 1024
        proc = self.proc
        try:
            while True:
                chunk = os.read(fd, 65536)
                if not chunk:
                    return
                with self.output_lock:
                    self.output.extend(chunk)
                    if len(self.output) > 4 * OUTPUT_TAIL:
                        del self.output[: len(self.output) - OUTPUT_TAIL]
                    self.printed += len(chunk)
                if self.printed > limit and proc is not None:
                    self.over_output = proc
                    kill_process(proc)
        except OSError:
            return
        finally:
            os.close(fd)

    def kill(self) -> None:
        if self.proc is not None:
            kill_process(self.proc)
            for fd in (self.req_w, self.rep_r):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self.proc = None
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
        raise protocol.ProtocolError(f"a {type(value).__name__} cannot be sent to the worker")

    def _send(self, message: dict) -> None:
        frame = protocol.encode(message, cb_ref=self._ref)
        try:
            protocol.write_frame(self.req_w, frame)
        except OSError:
            pass  # the worker is gone: the next read reports how it ended

    def _receive(self, deadline: float, during: str = "running your code") -> dict:
        header = self._read(8, deadline, during)
        (n,) = struct.unpack("<Q", header)
        if n > protocol.MAX_FRAME:
            self.kill()
            raise StudentCodeError("protocol", "", f"the worker sent a {n}-byte message (limit {protocol.MAX_FRAME})")
        payload = self._read(n, deadline, during)
        gen = self.generation
        try:
            return protocol.decode(payload, obj=lambda v: RemoteObject(self, gen, v["id"], str(v.get("type", "?"))))
        except protocol.ProtocolError as exc:
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
                raise StudentCodeError("timeout", "", f"Timeout (>{self.test_timeout:g}s) while {during}: your code "
                                       "did not return in time (an endless loop?)")
            if now >= self.next_poll:  # at most every 0.5 s, not per message: psutil scans all of /proc
                self.next_poll = now + 0.5
                rss_mb, n_procs = tree_usage(self.proc.pid) if self.proc is not None else (0.0, 0)
                if rss_mb > 1.5 * self.memory_mb:
                    self.kill()
                    raise StudentCodeError("memory", "", f"used more than {1.5 * self.memory_mb:g} MiB of memory "
                                           "and was stopped")
                if n_procs > MAX_PROCESSES:
                    self.kill()
                    raise StudentCodeError("crashed", "", f"started more than {MAX_PROCESSES} processes and was stopped")
            ready, _, _ = select.select([self.rep_r], [], [], min(0.1, max(deadline - now, 0.001)))
            if not ready:
                continue
            try:
                chunk = os.read(self.rep_r, min(n - got, 1 << 20))
            except BlockingIOError:
                continue
            if not chunk:
                raise self._ended(during)
            parts.append(chunk)
            got += len(chunk)
        return b"".join(parts)

    def _ended(self, during: str) -> StudentCodeError:
        proc = self.proc
        code = proc.wait() if proc is not None else None
        over = self.over_output
        self.kill()
        if over is not None and over is proc:
            return StudentCodeError("output", "", f"printed more than the {self.output_mb} MiB output limit and was stopped")
        if code is not None and code < 0:
            name = signal.Signals(-code).name if -code in signal.Signals._value2member_map_ else str(-code)
            how = f"was killed by signal {name}"
        else:
            how = f"exited with code {code}"
        return StudentCodeError("crashed", "", f"the process running your code {how} while {during} "
                                "(os._exit / sys.exit at import / a crash?)")

    def _error(self, reply: dict, cause: str = "error") -> StudentCodeError:
        if reply.get("reference"):
            self.reference = str(reply["reference"])
            return StudentCodeError("reference", "", f"calls the reference implementation ({reply['reference']})",
                                    str(reply.get("traceback", "")))
        return StudentCodeError(cause, str(reply.get("type", "Error")), str(reply.get("message", "")),
                                str(reply.get("traceback", "")))

    def request(self, op: str, **fields) -> Any:
        """Send one request and serve callbacks until its reply; the reply's value (or StudentCodeError)."""
        waiting = False
        try:
            if self.proc is None or self.proc.poll() is not None:
                self._start()
            if self.import_error is not None:
                raise self.import_error
            # starting the worker (torch's import on a busy machine) does not count against the test
            self.deadline = min(time.monotonic() + max(self.test_left, 0.0), self.budget_end)
            waiting = True
            self._send({"op": op, **fields})
            while True:
                reply = self._receive(self.deadline)
                kind = reply.get("kind")
                if kind == "result":
                    if reply.get("reference"):
                        raise self._error(reply)
                    return reply.get("value")
                if kind == "error":
                    raise self._error(reply)
                if kind == "callback":
                    started = time.monotonic()
                    self._callback(reply)
                    self.deadline = min(self.deadline + time.monotonic() - started, self.budget_end)  # the test's time
                    continue
                self.kill()
                raise StudentCodeError("protocol", "", f"unexpected message from the worker: {str(reply)[:200]}")
        except StudentCodeError as exc:
            self.causes.append(exc.cause)
            raise
        finally:
            if waiting:
                self.test_left = self.deadline - time.monotonic()

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
