"""Tensor comparison for the graded tests: ``torch.testing.assert_close``'s rule and messages, lighter.

Why not torch's own: its first call imports ``torch.distributed.tensor`` (to recognise DTensors),
which pulls in sympy and mpmath, about a second of CPU in the trusted test process; the graded
tests never see a DTensor, and ``coursekit check`` must answer in a few seconds (issue 22).

The rule is torch's (tests/test_grading_compare.py holds the two together on random inputs):
``actual`` and ``expected`` must be tensors of the same shape and dtype, and every element must
satisfy ``|actual - expected| <= atol + rtol * |expected|``; NaN is never close (torch's default
``equal_nan=False``), equal infinities are. Default tolerances by dtype, as torch's:

=========================  ========  ========
dtype                      rtol      atol
=========================  ========  ========
float16                    1e-3      1e-5
bfloat16                   1.6e-2    1e-5
float32                    1.3e-6    1e-5
float64                    1e-7      1e-7
integers and bool          0         0
=========================  ========  ========
"""

from __future__ import annotations

from collections.abc import Callable

import torch

DEFAULT_TOLERANCES = {torch.float16: (1e-3, 1e-5), torch.bfloat16: (1.6e-2, 1e-5),
                      torch.float32: (1.3e-6, 1e-5), torch.float64: (1e-7, 1e-7)}
"""dtype -> (rtol, atol) when neither is given (other dtypes: exact)."""

Message = str | Callable[[str], str] | None


def _fail(default: str, msg: Message) -> AssertionError:
    if callable(msg):
        return AssertionError(msg(default))
    return AssertionError(msg if msg is not None else default)


def _index(flat: int, shape: torch.Size) -> str:
    if len(shape) == 0:
        return ""
    idx = []
    for size in reversed(shape):
        idx.append(flat % size)
        flat //= size
    return f" at index {tuple(reversed(idx))}"


def _mismatch_message(actual: torch.Tensor, expected: torch.Tensor, close: torch.Tensor,
                      rtol: float, atol: float) -> str:
    """torch's wording: how many elements differ, and the greatest absolute and relative difference."""
    total, bad = expected.numel(), int((~close).sum())
    if expected.ndim == 0:
        a, e = actual.item(), expected.item()
        abs_diff = abs(a - e)
        rel_diff = abs_diff / abs(e) if e != 0 else float("inf")
        return (f"Scalars are not close!\n\nExpected {e} but got {a}.\n"
                f"Absolute difference: {abs_diff} (up to {atol} allowed)\n"
                f"Relative difference: {rel_diff} (up to {rtol} allowed)")
    a, e = actual.double().reshape(-1), expected.double().reshape(-1)  # (N,)
    ok = close.reshape(-1)  # (N,)
    abs_diff = torch.where(ok, torch.zeros_like(a), (a - e).abs())
    rel_diff = torch.where(ok, torch.zeros_like(a), (a - e).abs() / e.abs())
    # the greatest difference, a NaN counting as the greatest (torch reports it as nan too)
    i_abs, i_rel = int(abs_diff.nan_to_num(nan=float("inf")).argmax()), int(rel_diff.nan_to_num(nan=float("inf")).argmax())
    return (f"Tensor-likes are not close!\n\nMismatched elements: {bad} / {total} ({bad / total:.1%})\n"
            f"Greatest absolute difference: {abs_diff[i_abs].item()}{_index(i_abs, expected.shape)} "
            f"(up to {atol} allowed)\n"
            f"Greatest relative difference: {rel_diff[i_rel].item()}{_index(i_rel, expected.shape)} "
            f"(up to {rtol} allowed)")


def assert_close(actual, expected, *, rtol: float | None = None, atol: float | None = None,
                 msg: Message = None) -> None:
    """Raise AssertionError unless ``actual`` and ``expected`` (tensors) are close (see module doc).

    ``rtol``/``atol``: both or neither (then the dtype's defaults); ``msg``: a string replacing the
    message, or a function of the default message returning the one to raise.
    """
    if (rtol is None) != (atol is None):
        raise ValueError(f"give both rtol and atol or neither, got rtol={rtol!r}, atol={atol!r}")
    for name, value in (("actual", actual), ("expected", expected)):
        if not isinstance(value, torch.Tensor):
            raise _fail(f"Expected {name} to be a tensor, but got {type(value).__name__}.", msg)
    if actual.shape != expected.shape:
        raise _fail(f"The values for attribute 'shape' do not match: {actual.shape} != {expected.shape}.", msg)
    if actual.dtype != expected.dtype:
        raise _fail(f"The values for attribute 'dtype' do not match: {actual.dtype} != {expected.dtype}.", msg)
    if rtol is None:
        rtol, atol = DEFAULT_TOLERANCES.get(expected.dtype, (0.0, 0.0))
    a, e = actual.detach().cpu(), expected.detach().cpu()
    if not (a.is_floating_point() or a.is_complex()):
        a, e = a.double(), e.double()
    close = torch.isclose(a, e, rtol=rtol, atol=atol, equal_nan=False)  # |a - e| <= atol + rtol |e|
    if not bool(close.all()):
        raise _fail(_mismatch_message(a, e, close, rtol, atol), msg)
