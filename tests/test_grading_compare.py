"""coursekit.grading.compare.assert_close (the graded tests' comparison) against its reference,
torch.testing.assert_close: on random tensors, tolerances, NaNs and infinities, one raises exactly
when the other does, with the same count of mismatched elements; shape and dtype mismatches and
``msg`` behave alike; and it never imports sympy (the second it saves is why it exists)."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from coursekit.grading.compare import assert_close


def _outcome(fn, actual, expected, **kw) -> str | None:
    try:
        fn(actual, expected, **kw)
    except AssertionError as exc:
        return str(exc)
    return None


def _mismatched(message: str) -> str:
    m = re.search(r"Mismatched elements: (\d+ / \d+)", message)
    return m.group(1) if m else "scalar"


SPECIAL = st.sampled_from([0.0, 1.0, -1.0, 1e-6, 1e3, float("nan"), float("inf"), -float("inf")])


@st.composite
def pairs(draw):
    dtype = draw(st.sampled_from([torch.float32, torch.float64, torch.float16]))
    shape = tuple(draw(st.lists(st.integers(1, 4), min_size=0, max_size=3)))
    n = 1
    for s in shape:
        n *= s
    base = draw(st.lists(st.one_of(st.floats(-100, 100, width=16), SPECIAL), min_size=n, max_size=n))
    noise = draw(st.lists(st.one_of(st.just(0.0), st.floats(-1e-3, 1e-3), st.floats(-10, 10), SPECIAL),
                          min_size=n, max_size=n))
    expected = torch.tensor(base, dtype=torch.float64).reshape(shape)
    actual = expected + torch.tensor(noise, dtype=torch.float64).reshape(shape)
    tol = draw(st.one_of(st.none(), st.tuples(st.sampled_from([0.0, 1e-6, 1e-3, 0.1]), st.sampled_from([0.0, 1e-7, 1e-3, 1.0]))))
    return actual.to(dtype), expected.to(dtype), tol


@settings(max_examples=400, deadline=None)
@given(pairs())
def test_raises_exactly_when_torch_does_with_the_same_mismatch_count(case):
    actual, expected, tol = case
    kw = {} if tol is None else {"rtol": tol[0], "atol": tol[1]}
    ours, theirs = _outcome(assert_close, actual, expected, **kw), _outcome(torch.testing.assert_close, actual, expected, **kw)
    assert (ours is None) == (theirs is None), (actual, expected, kw, ours, theirs)
    if ours is not None:
        assert _mismatched(ours) == _mismatched(theirs), (ours, theirs)


@pytest.mark.parametrize("actual,expected,word", [
    (torch.zeros(2, 3), torch.zeros(3, 2), "'shape' do not match: torch.Size([2, 3]) != torch.Size([3, 2])"),
    (torch.zeros(2), torch.zeros(2, dtype=torch.float64), "'dtype' do not match: torch.float32 != torch.float64"),
    (torch.zeros(2).numpy(), torch.zeros(2), "Expected actual to be a tensor, but got ndarray"),
])
def test_shape_dtype_and_type_mismatches_say_what_differs(actual, expected, word):
    message = _outcome(assert_close, actual, expected)
    assert message is not None and word in message, message
    if isinstance(actual, torch.Tensor):  # torch words these two the same way
        assert word in _outcome(torch.testing.assert_close, actual, expected)


def test_msg_replaces_or_wraps_the_default_message():
    a, e = torch.tensor([1.0, 2.0]), torch.tensor([1.0, 2.5])
    assert _outcome(assert_close, a, e, msg="mine") == "mine"
    wrapped = _outcome(assert_close, a, e, msg=lambda m: f"x0_hat is wrong: {m}")
    assert wrapped.startswith("x0_hat is wrong: Tensor-likes are not close!") and "1 / 2 (50.0%)" in wrapped
    assert "Greatest absolute difference: 0.5 at index (1,)" in wrapped
    with pytest.raises(ValueError, match="both rtol and atol"):
        assert_close(a, a, rtol=1e-3)


def test_does_not_import_sympy():
    code = ("import sys, torch; from coursekit.grading.compare import assert_close; "
            "assert_close(torch.ones(3), torch.ones(3)); print('sympy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr
