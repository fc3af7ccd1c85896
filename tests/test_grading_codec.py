"""The wire format between the grader and the untrusted worker (coursekit/grading/codec.py).

Whatever bytes the worker sends, the trusted side gets plain data or a ProtocolError naming what is
wrong: never another exception, never an object it did not ask for, never an unpickled one. Plain
data survives a round trip exactly (dtype, shape, NaN and infinities included).
"""

from __future__ import annotations

import json
import math
import pickle
import struct

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from coursekit.grading import codec
from coursekit.grading.codec import MAX_DEPTH, MAX_FRAME, ProtocolError, decode, encode, frame_length

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
DTYPES = sorted(codec.DTYPES)


def _payload(value, **kwargs) -> bytes:
    frame = encode(value, **kwargs)
    assert frame_length(frame[:8]) == len(frame) - 8
    return frame[8:]


def _frame(head, *buffers: bytes) -> bytes:
    """A payload from a JSON tree written by hand and the raw bytes after it."""
    text = json.dumps(head).encode()
    return struct.pack("<I", len(text)) + text + b"".join(buffers)


def _same(a, b) -> bool:
    """Equal values of the same types (arrays: dtype, shape and bits; NaN equals NaN)."""
    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.dtype == b.dtype and a.shape == b.shape and \
            torch.equal(torch.nan_to_num(a), torch.nan_to_num(b)) and a.requires_grad == b.requires_grad
    if isinstance(a, np.ndarray):
        return type(b) is np.ndarray and a.dtype == b.dtype and a.shape == b.shape and \
            a.tobytes() == b.tobytes()
    if isinstance(a, np.generic):
        return type(b) is type(a) and a.tobytes() == b.tobytes()
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return type(b) is dict and list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    return type(a) is type(b) and a == b


arrays = st.sampled_from(DTYPES).flatmap(
    lambda d: hnp.arrays(np.dtype(d), hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4)))
scalars = st.none() | st.booleans() | st.integers(-2**63 + 1, 2**63 - 1) | st.floats(allow_nan=True) | st.text(max_size=8)
plain = st.recursive(
    scalars | arrays,
    lambda inner: (st.lists(inner, max_size=4) | st.lists(inner, max_size=4).map(tuple)
                   | st.dictionaries(st.text(max_size=4) | st.integers(-5, 5), inner, max_size=4)),
    max_leaves=12)


@SETTINGS
@given(plain)
def test_plain_data_round_trips_exactly(value):
    assert _same(value, decode(_payload(value)))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64, torch.int64, torch.uint8, torch.bool, torch.complex64])
def test_tensors_cross_as_plain_tensors(dtype):
    t = (torch.arange(6) % 3).to(dtype).reshape(2, 3)
    t = t.requires_grad_(True) if dtype.is_floating_point else t
    out = decode(_payload({"t": t, "view": t.detach().T, "scalar": np.float32(2.5)}))
    assert _same(t.detach().requires_grad_(t.requires_grad), out["t"])
    assert _same(t.detach().T.contiguous(), out["view"])  # a strided view arrives as its values
    assert _same(np.float32(2.5), out["scalar"])
    assert type(decode(_payload(t), as_torch=False)) is np.ndarray  # the worker's side can ask for arrays


def test_subclasses_arrive_as_their_base_class():
    class Always(np.ndarray):
        def __eq__(self, other):  # the ndarray_subclass attack: "equal" to anything
            return True

    class Sneaky(int):
        pass

    out = decode(_payload([np.zeros(3).view(Always), Sneaky(7), True]))
    assert type(out[0]) is np.ndarray and type(out[1]) is int and out[1] == 7 and out[2] is True


@pytest.mark.parametrize("value", [np.array([object()]), {1, 2}, {(1, 2): 3}, object(), b"bytes",
                                   np.zeros(2, dtype="datetime64[s]")])
def test_encode_refuses_what_is_not_plain_data(value):
    with pytest.raises(ProtocolError, match="cannot cross"):
        encode(value)


def test_encode_refuses_deep_nesting_and_oversized_messages():
    nested = []
    for _ in range(MAX_DEPTH + 2):
        nested = [nested]
    with pytest.raises(ProtocolError, match=f"nested deeper than {MAX_DEPTH} levels"):
        encode(nested)
    with pytest.raises(ProtocolError, match="exceeds the"):
        encode(np.zeros(MAX_FRAME // 8 + 1))


# ------------------------------------------------------------------------------ what a hostile worker can send
def _decode_or_refuse(payload: bytes, **kwargs):
    """decode(), with every way to unpickle disabled: a ProtocolError (with a reason) or plain data."""
    forbidden = pytest.MonkeyPatch()

    def no_pickle(*args, **kwargs):
        raise AssertionError("the codec tried to unpickle")

    for name in ("loads", "load", "Unpickler"):
        forbidden.setattr(pickle, name, no_pickle)
    forbidden.setattr(np, "load", no_pickle)
    try:
        value = decode(payload, **kwargs)
    except ProtocolError as exc:
        assert str(exc).strip(), "a refusal must say why"
        return exc
    finally:
        forbidden.undo()
    _assert_plain(value)
    return value


def _assert_plain(value) -> None:
    if isinstance(value, (list, tuple)):
        for v in value:
            _assert_plain(v)
    elif isinstance(value, dict):
        for k, v in value.items():
            assert type(k) in (str, int)
            _assert_plain(v)
    elif isinstance(value, np.ndarray):
        assert type(value) is np.ndarray and value.dtype.name in codec.DTYPES
    elif isinstance(value, torch.Tensor):
        assert type(value) is torch.Tensor
    else:
        assert value is None or type(value) in (bool, int, float, str) or type(value).__module__ == "numpy", value


@SETTINGS
@given(st.binary(max_size=256))
def test_random_bytes_are_refused_or_plain(data):
    _decode_or_refuse(data)


@SETTINGS
@given(plain, st.data())
def test_every_truncation_is_refused(value, data):
    payload = _payload(value)
    cut = data.draw(st.integers(0, len(payload) - 1))
    refusal = _decode_or_refuse(payload[:cut])
    assert isinstance(refusal, ProtocolError), f"{cut} of {len(payload)} bytes were accepted"
    refusal = _decode_or_refuse(payload + b"\0")
    assert isinstance(refusal, ProtocolError) and "no array accounts for" in str(refusal)


@SETTINGS
@given(plain, st.data())
def test_flipped_bytes_are_refused_or_plain(value, data):
    payload = bytearray(_payload(value))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(payload) - 1))
        payload[i] = data.draw(st.integers(0, 255))
    _decode_or_refuse(bytes(payload))


json_trees = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["t", "v", "id", "name", "dtype", "shape", "torch", "grad", "scalar", "state", "x"]),
        inner | st.sampled_from(["nd", "list", "tuple", "dict", "obj", "cb", "attr", "gen", *DTYPES]), max_size=5),
    max_leaves=15)


@SETTINGS
@given(json_trees, st.binary(max_size=64))
def test_hostile_headers_are_refused_or_plain(tree, tail):
    _decode_or_refuse(_frame(tree, tail))


@pytest.mark.parametrize("payload, reason", [
    (b"", "truncated message (0 bytes"),
    (struct.pack("<I", 99) + b"{}", "message header of 99 bytes is longer than the message"),
    (struct.pack("<I", 2) + b"\xff\xfe", "message header is not JSON"),
    (struct.pack("<I", 3) + b"{x}", "message header is not JSON"),
    (struct.pack("<I", 100_000) + b"[" * 100_000, "message header nested deeper than"),  # past the recursion limit
    (_frame(json.loads('{"t": "list", "v": [' * 50 + "]}" * 50)), f"nested deeper than {MAX_DEPTH} levels"),
    (_frame({"t": "nd", "dtype": "object", "shape": [1]}, b"\0" * 8), "bad array description"),
    (_frame({"t": "nd", "dtype": "float32", "shape": [-1]}), "bad array description"),
    (_frame({"t": "nd", "dtype": "float32", "shape": [True]}, b"\0" * 4), "bad array description"),
    (_frame({"t": "nd", "dtype": "uint8", "shape": [1] * 17}, b"\0"), "bad array description"),
    (_frame({"t": "nd", "dtype": "float64", "shape": [2**62, 2**62]}), "run past the end of the message"),
    (_frame({"t": "nd", "dtype": "int8", "shape": [0, 2**63]}), "bad array shape"),
    (_frame({"t": "nd", "dtype": "float32", "shape": [3]}, b"\0" * 8), "run past the end of the message"),
    (_frame({"t": "obj", "id": 1, "type": "os.system"}), "unexpected value"),  # no handle builder given
    (_frame({"t": "gen", "state": None}), "unexpected value"),  # generators cross only towards the worker
    (_frame({"t": "dict", "v": [[[1], 2]]}), "bad dict entry"),
    (_frame({"t": ["list"], "v": []}), "unexpected value"),
    (_frame({"t": "set", "v": [1]}), "unexpected value"),
])
def test_malformed_messages_name_what_is_wrong(payload, reason):
    refusal = _decode_or_refuse(payload)
    assert isinstance(refusal, ProtocolError) and reason in str(refusal), repr(refusal)[:300]


def test_handles_are_built_only_by_the_callbacks_given():
    seen = []
    value = decode(_frame({"t": "list", "v": [{"t": "obj", "id": 4, "type": "x.Y"}, {"t": "attr", "name": "f"}]}),
                   obj=lambda v: seen.append(v) or "handle", attr=lambda v: "attribute")
    assert value == ["handle", "attribute"] and seen == [{"t": "obj", "id": 4, "type": "x.Y"}]
    refusal = _decode_or_refuse(_frame({"t": "obj", "id": "4"}), obj=lambda v: "handle")
    assert isinstance(refusal, ProtocolError)  # an id must be an int


def test_frame_length_refuses_oversized_frames():
    assert frame_length(struct.pack("<Q", MAX_FRAME)) == MAX_FRAME
    with pytest.raises(ProtocolError, match=f"a {MAX_FRAME + 1}-byte message \\(limit {MAX_FRAME}\\)"):
        frame_length(struct.pack("<Q", MAX_FRAME + 1))
