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
trusted side gets plain data it can compare with its own code.
"""

from __future__ import annotations

import json
import math
import os
import struct
from typing import Any, Callable

MAX_FRAME = 64 * 1024 * 1024
"""Largest message either side accepts (bytes): far above what any exercise returns."""
MAX_DEPTH = 32
"""Nesting depth of lists / dicts accepted."""
DTYPES = frozenset({"bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
                    "float16", "float32", "float64", "complex64", "complex128"})
"""Array dtypes that may cross (little-endian, native layout)."""


class ProtocolError(Exception):
    """A malformed or oversized message (the worker is broken or hostile)."""


def _np():
    import numpy

    return numpy


def _torch_if_loaded():
    import sys

    torch = sys.modules.get("torch")
    # Another thread may be importing torch right now (a worker started early: tests/exercises/conftest.py);
    # until torch.Tensor and torch.Generator exist, no value can be either.
    return torch if hasattr(torch, "Tensor") and hasattr(torch, "Generator") else None


def encode(value: Any, obj_ref: Callable[[Any], dict] | None = None, cb_ref: Callable[[Any], dict] | None = None,
           mark_grad: bool = True) -> bytes:
    """Frame ``value``. Values that are not plain data go through ``obj_ref`` (worker side: store
    the object, return a handle) or ``cb_ref`` (trusted side: register a callback); without one
    they raise ProtocolError."""
    buffers: list[bytes] = []

    def array(a, is_torch: bool, grad: bool) -> dict:
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
        buffers.append(a.tobytes())
        return {"t": "nd", "dtype": dtype, "shape": list(a.shape), "torch": is_torch, "grad": grad}

    def enc(v: Any, depth: int) -> Any:
        if depth > MAX_DEPTH:
            raise ProtocolError(f"value nested deeper than {MAX_DEPTH} levels")
        if v is None or type(v) in (bool, str):
            return v
        if type(v) is int:
            return v if abs(v) < 2**63 else float(v)
        if type(v) is float:
            return v
        np = _np()
        torch = _torch_if_loaded()
        if torch is not None and isinstance(v, torch.Tensor):
            t = torch.Tensor.detach(v).cpu()
            if t.dtype == torch.bfloat16:
                t = t.float()
            return array(t.resolve_conj().resolve_neg().numpy(), True, bool(mark_grad and v.requires_grad))
        if torch is not None and isinstance(v, torch.Generator):  # its state crosses; the copy draws the same numbers
            return {"t": "gen", "state": enc(v.get_state(), depth + 1)}
        if isinstance(v, (np.ndarray, np.generic)):
            out = array(v, False, False)
            if isinstance(v, np.generic):
                out["scalar"] = True
            return out
        if isinstance(v, bool):
            return bool(v)
        if isinstance(v, int):
            return int.__int__(v)
        if isinstance(v, float):
            return float.__float__(v)
        if isinstance(v, (list, tuple)) and type(v) in (list, tuple):
            return {"t": type(v).__name__, "v": [enc(x, depth + 1) for x in v]}
        if type(v) is dict and all(type(k) in (str, int) for k in v):
            return {"t": "dict", "v": [[k, enc(x, depth + 1)] for k, x in v.items()]}
        if cb_ref is not None and callable(v):
            return cb_ref(v)
        if obj_ref is not None:
            return obj_ref(v)
        raise ProtocolError(f"a {type(v).__name__} cannot cross to the worker")

    head = json.dumps(enc(value, 0), separators=(",", ":")).encode()
    payload = b"".join([struct.pack("<I", len(head)), head, *buffers])
    if len(payload) > MAX_FRAME:
        raise ProtocolError(f"message of {len(payload)} bytes exceeds the {MAX_FRAME}-byte limit")
    return struct.pack("<Q", len(payload)) + payload


def decode(payload: bytes, obj: Callable[[dict], Any] | None = None, cb: Callable[[dict], Any] | None = None,
           attr: Callable[[dict], Any] | None = None, as_torch: bool = True, generators: bool = False) -> Any:
    """Plain data from one frame's payload (the part after the 8-byte length)."""
    if len(payload) < 4:
        raise ProtocolError("truncated message")
    (n_head,) = struct.unpack_from("<I", payload)
    if n_head > len(payload) - 4:
        raise ProtocolError("message header longer than the message")
    try:
        tree = json.loads(payload[4:4 + n_head].decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ProtocolError(f"message header is not JSON: {exc}") from None
    offset = [4 + n_head]
    np = _np()

    def array(spec: dict):
        dtype, shape = spec.get("dtype"), spec.get("shape")
        if dtype not in DTYPES or not isinstance(shape, list) or len(shape) > 16 or \
                not all(type(s) is int and s >= 0 for s in shape):
            raise ProtocolError(f"bad array description {spec!r:.200}")
        dt = np.dtype(dtype).newbyteorder("<")
        nbytes = math.prod(shape) * dt.itemsize
        start = offset[0]
        if start + nbytes > len(payload):
            raise ProtocolError("array bytes run past the end of the message")
        offset[0] = start + nbytes
        a = np.frombuffer(payload, dtype=dt, count=math.prod(shape), offset=start).astype(np.dtype(dtype)).reshape(shape)
        if spec.get("scalar") is True and a.ndim == 0:
            return a[()]
        if spec.get("torch") is True and as_torch:
            import torch

            t = torch.from_numpy(a.copy())
            if spec.get("grad") is True and t.is_floating_point():
                t.requires_grad_(True)
            return t
        return a

    def dec(v: Any, depth: int) -> Any:
        if depth > MAX_DEPTH:
            raise ProtocolError(f"value nested deeper than {MAX_DEPTH} levels")
        if v is None or type(v) in (bool, int, float, str):
            return v
        if type(v) is not dict:
            raise ProtocolError(f"unexpected JSON value {v!r:.100}")
        tag = v.get("t")
        if tag in ("list", "tuple") and type(v.get("v")) is list:
            items = [dec(x, depth + 1) for x in v["v"]]
            return items if tag == "list" else tuple(items)
        if tag == "dict" and type(v.get("v")) is list:
            out = {}
            for pair in v["v"]:
                if type(pair) is not list or len(pair) != 2 or type(pair[0]) not in (str, int):
                    raise ProtocolError("bad dict entry")
                out[pair[0]] = dec(pair[1], depth + 1)
            return out
        if tag == "nd":
            return array(v)
        if tag == "obj" and obj is not None and type(v.get("id")) is int:
            return obj(v)
        if tag == "cb" and cb is not None and type(v.get("id")) is int:
            return cb(v)
        if tag == "attr" and attr is not None and type(v.get("name")) is str:
            return attr(v)
        if tag == "gen" and generators:  # worker side only: a torch.Generator rebuilt from its state
            import torch

            state = dec(v.get("state"), depth + 1)
            if not isinstance(state, torch.Tensor) or state.dtype != torch.uint8:
                raise ProtocolError("bad generator state")
            generator = torch.Generator()
            generator.set_state(state)
            return generator
        raise ProtocolError(f"unexpected value {str(v)[:100]}")

    value = dec(tree, 0)
    if offset[0] != len(payload):
        raise ProtocolError("message has bytes no array accounts for")
    return value


def write_frame(fd: int, frame: bytes) -> None:
    view = memoryview(frame)
    while view:
        view = view[os.write(fd, view):]


def read_frame_blocking(fd: int) -> bytes:
    """The payload of the next frame (worker side: blocking reads). EOFError when the peer is gone."""
    head = _read_exact(fd, 8)
    (n,) = struct.unpack("<Q", head)
    if n > MAX_FRAME:
        raise ProtocolError(f"message of {n} bytes exceeds the limit")
    return _read_exact(fd, n)


def _read_exact(fd: int, n: int) -> bytes:
    parts, got = [], 0
    while got < n:
        chunk = os.read(fd, min(n - got, 1 << 20))
        if not chunk:
            raise EOFError("the other side closed the channel")
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)
