"""The wire format between the trusted grader and the untrusted worker: plain data only, never pickle.

One message is a frame: an 8-byte little-endian length N, then N bytes: a 4-byte JSON length J,
J bytes of JSON, then the raw bytes of every array the JSON mentions, in order. A value is

- ``None``, a bool, an int, a float (NaN and inf included) or a str: the JSON value itself;
- ``{"t": "list"|"tuple", "v": [...]}``, ``{"t": "dict", "v": [[key, value], ...]}`` (str/int keys);
- ``{"t": "nd", "dtype": "float32", "shape": [3, 4], "torch": bool, "grad": bool}``: an array whose
  bytes follow the JSON. Only plain numeric dtypes cross (no object arrays); a torch tensor
  becomes its plain CPU values (``torch``: decode as a tensor), a subclass becomes its base class;
- ``{"t": "obj", "id": n, "type": "module.Class"}``: a handle to an object that stays in the
  worker (a FiLM layer, an executor, a bound method); ``{"t": "attr", "name": s}``: an attribute
  of the student's module; ``{"t": "cb", "id": n}``: a callable that stays on the trusted side;
  ``{"t": "gen", "state": <uint8 array>}``: a torch.Generator (trusted -> worker only), rebuilt
  from its state so the worker draws the same numbers the test's generator would.

Decoding builds fresh base-class objects from the JSON and the bytes, checks every dtype, shape
and length against the frame, and caps depth and size, so whatever the worker sends, the
trusted side gets plain data it can compare with its own code (tests/test_grading_codec.py
feeds it random and truncated bytes).
"""

from __future__ import annotations

import json
import math
import os
import struct
import sys
from typing import Any, Callable

MAX_FRAME = 64 * 1024 * 1024
"""Largest message either side accepts (bytes): far above what any exercise returns."""
MAX_DEPTH = 32
"""Nesting depth of lists / dicts accepted."""
MAX_DIMS = 16
"""Most dimensions an array may have."""
DTYPES = frozenset({"bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
                    "float16", "float32", "float64", "complex64", "complex128"})
"""Array dtypes that may cross (little-endian, native layout)."""


class ProtocolError(Exception):
    """A malformed or oversized message (the worker is broken or hostile)."""


def _np():
    import numpy

    return numpy


def _torch_if_loaded():
    """torch if it is loaded (a tensor can only exist then), else None."""
    torch = sys.modules.get("torch")
    # Another thread may be importing torch right now (a worker started early: tests/exercises/conftest.py);
    # until torch.Tensor and torch.Generator exist, no value can be either.
    return torch if hasattr(torch, "Tensor") and hasattr(torch, "Generator") else None


class _Encoder:
    """Turns one value into the JSON tree and the array buffers of a frame."""

    def __init__(self, obj_ref: Callable[[Any], dict] | None, cb_ref: Callable[[Any], dict] | None,
                 mark_grad: bool) -> None:
        self.obj_ref, self.cb_ref, self.mark_grad = obj_ref, cb_ref, mark_grad
        self.buffers: list[bytes] = []

    def array(self, a, is_torch: bool, grad: bool) -> dict:
        np = _np()
        a = np.asarray(a)
        if type(a) is not np.ndarray:
            a = np.array(a, copy=True).view(np.ndarray)
        if not a.flags.c_contiguous:
            a = a.copy(order="C")
        dtype = a.dtype.newbyteorder("=").name if a.dtype.byteorder not in "=|" else a.dtype.name
        if dtype not in DTYPES:
            raise ProtocolError(f"arrays of dtype {a.dtype} cannot cross (allowed: {sorted(DTYPES)})")
        a = a.astype(a.dtype.newbyteorder("<"), copy=False)
        self.buffers.append(a.tobytes())
        return {"t": "nd", "dtype": dtype, "shape": list(a.shape), "torch": is_torch, "grad": grad}

    def value(self, v: Any, depth: int) -> Any:
        if depth > MAX_DEPTH:
            raise ProtocolError(f"value nested deeper than {MAX_DEPTH} levels")
        if v is None or type(v) in (bool, str, float):
            return v
        if type(v) is int:
            return v if abs(v) < 2**63 else float(v)
        numeric = self.numeric(v, depth)
        if numeric is not None:
            return numeric
        if isinstance(v, (list, tuple)) and type(v) in (list, tuple):
            return {"t": type(v).__name__, "v": [self.value(x, depth + 1) for x in v]}
        if type(v) is dict and all(type(k) in (str, int) for k in v):
            return {"t": "dict", "v": [[k, self.value(x, depth + 1)] for k, x in v.items()]}
        if self.cb_ref is not None and callable(v):
            return self.cb_ref(v)
        if self.obj_ref is not None:
            return self.obj_ref(v)
        raise ProtocolError(f"a {type(v).__name__} cannot cross to the worker")

    def numeric(self, v: Any, depth: int) -> Any:
        """Tensors, generators, numpy arrays and scalars, and subclasses of bool/int/float; None otherwise."""
        np = _np()
        torch = _torch_if_loaded()
        if torch is not None and isinstance(v, torch.Tensor):
            t = torch.Tensor.detach(v).cpu()
            if t.dtype == torch.bfloat16:
                t = t.float()
            return self.array(t.resolve_conj().resolve_neg().numpy(), True, bool(self.mark_grad and v.requires_grad))
        if torch is not None and isinstance(v, torch.Generator):  # its state crosses; the copy draws the same numbers
            return {"t": "gen", "state": self.value(v.get_state(), depth + 1)}
        if isinstance(v, (np.ndarray, np.generic)):
            out = self.array(v, False, False)
            if isinstance(v, np.generic):
                out["scalar"] = True
            return out
        if isinstance(v, bool):
            return bool(v)
        if isinstance(v, int):
            return int.__int__(v)
        if isinstance(v, float):
            return float.__float__(v)
        return None


def encode(value: Any, obj_ref: Callable[[Any], dict] | None = None, cb_ref: Callable[[Any], dict] | None = None,
           mark_grad: bool = True) -> bytes:
    """Frame ``value``. Values that are not plain data go through ``obj_ref`` (worker side: store
    the object, return a handle) or ``cb_ref`` (trusted side: register a callback); without one
    they raise ProtocolError."""
    encoder = _Encoder(obj_ref, cb_ref, mark_grad)
    head = json.dumps(encoder.value(value, 0), separators=(",", ":")).encode()
    payload = b"".join([struct.pack("<I", len(head)), head, *encoder.buffers])
    if len(payload) > MAX_FRAME:
        raise ProtocolError(f"message of {len(payload)} bytes exceeds the {MAX_FRAME}-byte limit")
    return struct.pack("<Q", len(payload)) + payload


class _Decoder:
    """Rebuilds plain values from one frame's JSON tree and array bytes (never trusting either)."""

    def __init__(self, payload: bytes, start: int, obj, cb, attr, as_torch: bool, generators: bool) -> None:
        self.payload, self.offset = payload, start
        self.handles = {"obj": (obj, "id", int), "cb": (cb, "id", int), "attr": (attr, "name", str)}
        self.as_torch, self.generators = as_torch, generators

    def array(self, spec: dict):
        np = _np()
        dtype, shape = spec.get("dtype"), spec.get("shape")
        if dtype not in DTYPES or not isinstance(shape, list) or len(shape) > MAX_DIMS or \
                not all(type(s) is int and s >= 0 for s in shape):
            raise ProtocolError(f"bad array description {spec!r:.200}")
        dt = np.dtype(dtype).newbyteorder("<")
        count = math.prod(shape)
        if count * dt.itemsize > len(self.payload) - self.offset:
            raise ProtocolError("array bytes run past the end of the message")
        try:
            a = np.frombuffer(self.payload, dtype=dt, count=count, offset=self.offset)
            a = a.astype(np.dtype(dtype)).reshape(shape)
        except (ValueError, OverflowError) as exc:  # e.g. a dimension beyond what numpy can index
            raise ProtocolError(f"bad array shape {shape!r:.100}: {exc}") from None
        self.offset += count * dt.itemsize
        if spec.get("scalar") is True and a.ndim == 0:
            return a[()]
        if spec.get("torch") is True and self.as_torch:
            return self.tensor(a, spec.get("grad") is True)
        return a

    @staticmethod
    def tensor(a, grad: bool):
        import torch

        try:
            t = torch.from_numpy(a.copy())
        except TypeError as exc:  # a dtype torch has no tensor for
            raise ProtocolError(f"an array of dtype {a.dtype} cannot be a tensor: {exc}") from None
        if grad and t.is_floating_point():
            t.requires_grad_(True)
        return t

    def value(self, v: Any, depth: int) -> Any:
        if depth > MAX_DEPTH:
            raise ProtocolError(f"value nested deeper than {MAX_DEPTH} levels")
        if v is None or type(v) in (bool, int, float, str):
            return v
        if type(v) is not dict:
            raise ProtocolError(f"unexpected JSON value {v!r:.100}")
        tag = v.get("t")
        if type(tag) is not str:
            raise ProtocolError(f"unexpected value {str(v)[:100]}")
        if tag in ("list", "tuple") and type(v.get("v")) is list:
            items = [self.value(x, depth + 1) for x in v["v"]]
            return items if tag == "list" else tuple(items)
        if tag == "dict" and type(v.get("v")) is list:
            return self.mapping(v["v"], depth)
        if tag == "nd":
            return self.array(v)
        if tag in self.handles:
            build, key, kind = self.handles[tag]
            if build is not None and type(v.get(key)) is kind:
                return build(v)
        if tag == "gen" and self.generators:
            return self.generator(v, depth)
        raise ProtocolError(f"unexpected value {str(v)[:100]}")

    def mapping(self, pairs: list, depth: int) -> dict:
        out = {}
        for pair in pairs:
            if type(pair) is not list or len(pair) != 2 or type(pair[0]) not in (str, int):
                raise ProtocolError("bad dict entry")
            out[pair[0]] = self.value(pair[1], depth + 1)
        return out

    def generator(self, v: dict, depth: int):
        """Worker side only: a torch.Generator rebuilt from its state."""
        import torch

        state = self.value(v.get("state"), depth + 1)
        if not isinstance(state, torch.Tensor) or state.dtype != torch.uint8:
            raise ProtocolError("bad generator state")
        generator = torch.Generator()
        try:
            generator.set_state(state)
        except RuntimeError as exc:
            raise ProtocolError(f"bad generator state: {exc}") from None
        return generator


def decode(payload: bytes, obj: Callable[[dict], Any] | None = None, cb: Callable[[dict], Any] | None = None,
           attr: Callable[[dict], Any] | None = None, as_torch: bool = True, generators: bool = False) -> Any:
    """Plain data from one frame's payload (the part after the 8-byte length).

    ``obj`` / ``cb`` / ``attr`` build what a handle stands for (a handle without its builder is
    refused); ``generators``: accept torch.Generator states (worker side). Raises ProtocolError,
    naming what is wrong, for anything that is not a well-formed message.
    """
    if len(payload) < 4:
        raise ProtocolError(f"truncated message ({len(payload)} bytes, a message has at least 4)")
    (n_head,) = struct.unpack_from("<I", payload)
    if n_head > len(payload) - 4:
        raise ProtocolError(f"message header of {n_head} bytes is longer than the message ({len(payload)} bytes)")
    try:
        tree = json.loads(payload[4:4 + n_head].decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ProtocolError(f"message header is not JSON: {exc}") from None
    except RecursionError:  # JSON nested past the interpreter's limit (MAX_DEPTH refuses far less)
        raise ProtocolError(f"message header nested deeper than {MAX_DEPTH} levels") from None
    decoder = _Decoder(payload, 4 + n_head, obj, cb, attr, as_torch, generators)
    value = decoder.value(tree, 0)
    if decoder.offset != len(payload):
        raise ProtocolError("message has bytes no array accounts for")
    return value


def write_frame(fd: int, frame: bytes) -> None:
    """Write a whole frame to ``fd`` (blocking)."""
    view = memoryview(frame)
    while view:
        view = view[os.write(fd, view):]


def frame_length(header: bytes) -> int:
    """The payload length an 8-byte frame header announces; ProtocolError over MAX_FRAME."""
    (n,) = struct.unpack("<Q", header)
    if n > MAX_FRAME:
        raise ProtocolError(f"a {n}-byte message (limit {MAX_FRAME})")
    return n


def read_frame_blocking(fd: int) -> bytes:
    """The payload of the next frame (worker side: blocking reads). EOFError when the peer is gone."""
    return _read_exact(fd, frame_length(_read_exact(fd, 8)))


def _read_exact(fd: int, n: int) -> bytes:
    parts, got = [], 0
    while got < n:
        chunk = os.read(fd, min(n - got, 1 << 20))
        if not chunk:
            raise EOFError("the other side closed the channel")
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)
