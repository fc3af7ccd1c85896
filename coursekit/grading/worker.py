"""The untrusted side: a process that imports ONE student module and runs calls on request.

Started by :class:`coursekit.grading.sandbox.Sandbox` (inside bubblewrap where available, see
:mod:`coursekit.grading.bubblewrap`) as ``python -I -c ...`` with fd 0 = requests, a reply fd named
in the first message and fd 1/2 = a pipe the trusted side drains (what the student's code prints).
Nothing decided here is trusted: this process only computes values and sends them back as plain
data (:mod:`coursekit.grading.codec`); every comparison happens in the trusted pytest process.

Before the student's module is imported the worker applies its resource limits and replaces
the library's own implementation of the graded exercise (and any import of ``solutions``) by
something that raises :class:`ReferenceCalled`, so a submission cannot hand in the reference.
:func:`scale_model` and :func:`toy_clean_estimate` are stand-in networks the graded tests build
here (``sandbox.new``).
"""

from __future__ import annotations

import importlib
import os
import sys
import traceback
from typing import Any

from coursekit.grading import codec
from coursekit.grading.exercises import load_exercise

REQUEST_FD = 0
PRELOADABLE = ("torch",)
"""Modules the trusted side may ask the worker to import at boot, before the student's code: torch
then loads while the trusted process imports its own copy (two cores, one wait) instead of at the
first tensor a test sends (the wait of ``coursekit check`` would be both imports in a row)."""


class ReferenceCalled(PermissionError):
    """The submission called the library's reference implementation (or imported solutions/)."""


# The one piece of state outside the Worker: blanked library files (build.blank_reference) call
# reference_called() by module name, without a handle on the worker.
_STATE = {"reference_called": ""}


def reference_called(what: str) -> ReferenceCalled:
    """Record and return the error a replaced reference raises (also used by blanked library files)."""
    _STATE["reference_called"] = _STATE["reference_called"] or what
    return ReferenceCalled(f"calls the reference implementation ({what})")


def _apply_limits(settings: dict) -> None:
    try:
        import resource
    except ImportError:  # not POSIX: the trusted side still enforces time and memory
        return
    mb = 1024 * 1024
    limits = [(resource.RLIMIT_CORE, 0)]
    if settings.get("memory_mb"):
        limits.append((resource.RLIMIT_AS, int(settings["memory_mb"]) * mb))
    if settings.get("file_mb"):
        limits.append((resource.RLIMIT_FSIZE, int(settings["file_mb"]) * mb))
    if settings.get("cpu_s"):
        limits.append((resource.RLIMIT_CPU, int(settings["cpu_s"])))
    if settings.get("nproc"):
        limits.append((resource.RLIMIT_NPROC, int(settings["nproc"])))
    for which, value in limits:
        try:
            resource.setrlimit(which, (value, value))
        except (ValueError, OSError):
            pass


def _block_reference(source: str, objects: list[str], solutions_dir: str) -> None:
    """Swap the library's reference objects (in every loaded coursekit module that holds them) for
    raising stand-ins, and refuse ``solutions`` imports and reads from the solutions folder."""
    module = importlib.import_module(source)
    for name in objects:
        original = getattr(module, name, None)
        if original is None:
            continue
        label = f"{source}.{name}"

        def stand_in(*args, _label=label, **kwargs):
            raise reference_called(_label)

        if isinstance(original, type):
            stand_in = type(name, (), {"__init__": stand_in, "__new__": lambda cls, *a, _l=label, **k: (_ for _ in ()).throw(reference_called(_l))})
        for mod in list(sys.modules.values()):
            if getattr(mod, "__name__", "").startswith("coursekit") and getattr(mod, name, None) is original:
                setattr(mod, name, stand_in)

    prefix = os.path.join(solutions_dir, "") if solutions_dir else None

    def hook(event: str, args: tuple) -> None:
        if event == "import" and args and isinstance(args[0], str) and args[0].split(".")[0] == "solutions":
            raise reference_called("import solutions")
        if event == "open" and prefix and args and isinstance(args[0], (str, bytes)):
            path = os.fsdecode(args[0])
            if os.path.abspath(path).startswith(prefix):
                raise reference_called("reads solutions/")

    sys.addaudithook(hook)  # cannot be removed from Python code


def scale_model(w: float):
    """A stand-in network (x_t, t, cond) -> w * x_t (noise or velocity prediction) with one scalar
    parameter ``w``, for tests whose gradients must flow through the student's code into parameters:
    ``sandbox.new("coursekit.grading.worker:scale_model", 0.3)`` builds it here (torch is imported then)."""
    import torch
    from torch import nn

    class Scale(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.w = nn.Parameter(torch.tensor(float(w)))

        def forward(self, x: torch.Tensor, t=None, cond=None) -> torch.Tensor:
            return self.w * x

    return Scale()


def toy_clean_estimate(matrix: Any, t: float):
    """A stand-in guided head's ``clean`` for real-time chunking (exercise 11.2): x (B, T, D) ->
    (x0_hat, v), v = tanh(x.reshape(B, T D) @ matrix.T).reshape(B, T, D) (a "velocity" mixing every
    step and action dimension) and x0_hat = x - t v (flow's clean estimate). ``matrix`` (T D, T D).
    Built here (``sandbox.new("coursekit.grading.worker:toy_clean_estimate", M, 0.6)``) so the
    student's autograd runs through it; the graded test calls the same function for the reference."""
    import torch

    m = torch.as_tensor(matrix)
    t = float(t)

    def clean(x: torch.Tensor):
        v = torch.tanh(x.reshape(x.shape[0], -1) @ m.to(x.dtype).T).reshape(x.shape)
        return x - t * v, v

    return clean


class Worker:
    """Holds the student's module and the objects handed out as handles; answers requests."""

    def __init__(self, reply_fd: int) -> None:
        self.reply_fd = reply_fd
        self.objects: dict[int, Any] = {}
        self.module: Any = None

    # -- encoding helpers
    def _ref(self, value: Any) -> dict:
        key = id(value)
        self.objects[key] = value
        kind = type(value)
        return {"t": "obj", "id": key, "type": f"{getattr(kind, '__module__', '?')}.{getattr(kind, '__qualname__', '?')}"}

    def send(self, message: dict) -> None:
        try:
            frame = codec.encode(message, obj_ref=self._ref, mark_grad=False)
        except Exception as exc:  # noqa: BLE001 - e.g. an unsupported dtype: tell the trusted side
            frame = codec.encode({"kind": "error", "type": type(exc).__name__, "message": str(exc),
                                  "traceback": "", "reference": ""})
        codec.write_frame(self.reply_fd, frame)

    def receive(self) -> dict:
        payload = codec.read_frame_blocking(REQUEST_FD)
        return codec.decode(payload, obj=lambda v: self.objects[v["id"]], cb=self._callback,
                            attr=lambda v: getattr(self.module, v["name"]), generators=True)

    def _callback(self, spec: dict):
        def call_trusted(*args, **kwargs):
            self.send({"kind": "callback", "id": spec["id"], "args": list(args), "kwargs": kwargs})
            reply = self.serve(until=("cb_result", "cb_error"))
            if reply["op"] == "cb_error":
                raise RuntimeError(f"a function the test passed in failed: {reply.get('message', '')}")
            return reply.get("value")

        return call_trusted

    # -- requests
    def serve(self, until: tuple[str, ...] = ()) -> dict:
        """Answer requests until one whose op is in ``until`` arrives (returned), or forever."""
        while True:
            request = self.receive()
            op = request.get("op")
            if op in until:
                return request
            try:
                value = self.run(op, request)
            except BaseException as exc:  # noqa: BLE001 - everything the student's code raises is a result
                if isinstance(exc, KeyboardInterrupt):
                    raise
                self.send(self.error(exc))
            else:
                self.send({"kind": "result", "value": value, "reference": _STATE["reference_called"]})

    def run(self, op: str, request: dict) -> Any:
        target, args, kwargs = request.get("target"), request.get("args", []), request.get("kwargs", {})
        if op == "call":
            return target(*args, **kwargs)
        if op == "getattr":
            return getattr(target, request["name"])
        if op == "params":
            return {k: v for k, v in target.named_parameters()}
        if op == "state":
            return dict(target.state_dict())
        if op == "load":
            import torch

            state = {k: torch.as_tensor(v) for k, v in request["state"].items()}
            target.load_state_dict(state, strict=True)
            return None
        if op == "grad":
            return self.grad(target, args, kwargs, request.get("wrt", []), request.get("grad_output"))
        if op == "new":
            module_name, _, name = request["factory"].partition(":")
            if not module_name.startswith("coursekit."):
                raise ValueError(f"only coursekit objects can be built here, not {module_name!r}")
            return getattr(importlib.import_module(module_name), name)(*args, **kwargs)
        if op == "seed":
            import random

            import numpy

            random.seed(request["seed"])
            numpy.random.seed(request["seed"])
            if "torch" in sys.modules:
                sys.modules["torch"].manual_seed(request["seed"])
            return None
        raise ValueError(f"unknown request {op!r}")

    def grad(self, target, args: list, kwargs: dict, wrt: list, grad_output) -> Any:
        """(output, [gradient per wrt entry]): an int is a positional argument, an object its named parameters."""
        import torch

        args = list(args)
        inputs: list[torch.Tensor] = []
        layout: list[Any] = []
        for w in wrt:
            if isinstance(w, int):
                args[w] = torch.as_tensor(args[w]).detach().clone().requires_grad_(True)
                inputs.append(args[w])
                layout.append(None)
            else:
                names = [n for n, _ in w.named_parameters()]
                inputs.extend(p for _, p in w.named_parameters())
                layout.append(names)
        output = target(*args, **kwargs)
        if not isinstance(output, torch.Tensor):
            raise TypeError(f"expected a tensor to differentiate, got {type(output).__name__}")
        if not output.requires_grad:
            grads = [None] * len(inputs)
        else:
            seed = None if grad_output is None else torch.as_tensor(grad_output, dtype=output.dtype)
            if seed is None and output.numel() != 1:
                raise ValueError(f"output of shape {tuple(output.shape)} is not a scalar")
            grads = list(torch.autograd.grad(output, inputs, seed, allow_unused=True))
        result, i = [], 0
        for names in layout:
            if names is None:
                result.append(grads[i])
                i += 1
            else:
                result.append(dict(zip(names, grads[i:i + len(names)])))
                i += len(names)
        return [output, result]

    def error(self, exc: BaseException) -> dict:
        chain, seen, reference = exc, set(), _STATE["reference_called"]
        while chain is not None and id(chain) not in seen:
            seen.add(id(chain))
            if isinstance(chain, ReferenceCalled):
                reference = reference or str(chain)
            chain = chain.__cause__ or chain.__context__
        # start the traceback at the student's own code: the worker's frames above it are noise
        frames, student_file = exc.__traceback__, getattr(self.module, "__file__", None)
        while frames is not None and student_file and frames.tb_frame.f_code.co_filename != student_file:
            frames = frames.tb_next
        tb = "".join(traceback.format_exception(type(exc), exc, frames or exc.__traceback__, limit=8))
        return {"kind": "error", "type": type(exc).__name__, "message": str(exc)[:2000], "traceback": tb[-4000:],
                "reference": reference}


def main() -> int:
    """The worker process: settings, limits, the reference blocked, the student's module, then requests."""
    settings = codec.decode(codec.read_frame_blocking(REQUEST_FD))
    _apply_limits(settings)
    sys.dont_write_bytecode = True
    worker = Worker(int(settings["reply_fd"]))
    try:
        for name in settings.get("preload", []):
            if name in PRELOADABLE:
                importlib.import_module(name)
        _block_reference(settings["source"], settings["objects"], settings.get("solutions_dir", ""))
    except BaseException as exc:  # noqa: BLE001 - the library itself failed to import: report it
        worker.send({"kind": "booted", "error": f"{type(exc).__name__}: {exc}"})
        return 1
    worker.send({"kind": "booted", "error": ""})  # from here on the student's code runs
    try:
        worker.module = load_exercise(settings["exercise"], settings["folder"])
    except BaseException as exc:  # noqa: BLE001 - a broken module fails every test with this reason
        if isinstance(exc, KeyboardInterrupt):
            raise
        worker.send(worker.error(exc) | {"kind": "import_error"})
    else:
        worker.send({"kind": "ready"})
    try:
        worker.serve()
    except (EOFError, OSError, codec.ProtocolError):  # the trusted side is gone or closed the channel
        return 0
    return 0
