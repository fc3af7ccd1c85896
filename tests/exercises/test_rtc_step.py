"""Exercise 11.2 (rtc_step): real-time chunking's soft-mask weights and one guided update.

References: the weights of the RTC paper's eq. 5 written as a loop; the guidance g = J^T W (Y -
x0_hat) with J the full Jacobian from ``torch.autograd.functional.jacobian`` (the student's code
must get there with one vector-Jacobian product); the update out - scale * g as a closed form.
The stand-in network (:func:`coursekit.grading.worker.toy_clean_estimate`) mixes every step and
action dimension, so an error weighted in the wrong place shows. Each failure message names the
quantity that is wrong (constant or linear soft weights, the sign of g, W on the wrong axis).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from coursekit.grading.compare import assert_close
from coursekit.grading.worker import toy_clean_estimate

EXERCISE = "rtc_step"
FACTORY = "coursekit.grading.worker:toy_clean_estimate"


# ------------------------------------------------------------------------------ the weights
def reference_weights(n: int, d: int, L: int, schedule: str = "exp") -> np.ndarray:
    w = np.zeros(n)
    for j in range(n):
        if j < d:
            w[j] = 1.0
        elif j < L and schedule == "exp":
            c = (L - j) / (L - d + 1)
            w[j] = c * (math.exp(c) - 1.0) / (math.e - 1.0)
    return w


def _weights(student, n, d, L, schedule="exp") -> np.ndarray:
    got = student.rtc_weights(n, d, L, schedule)
    assert isinstance(got, np.ndarray), f"rtc_weights({n}, {d}, {L}) returned a {type(got).__name__}, which is not an ndarray"
    assert got.shape == (n,), f"rtc_weights({n}, {d}, {L}): expected shape ({n},), got {got.shape}"
    return got


def _fmt(values) -> str:
    return "[" + ", ".join(f"{float(v):.3g}" for v in values) + "]"


def _soft_diagnosis(soft: np.ndarray, ref: np.ndarray, d: int, L: int) -> str:
    """What is wrong with the soft weights W_d .. W_{L-1}, in words."""
    c = (L - np.arange(d, L)) / (L - d + 1.0)
    steps = np.diff(soft)
    if len(soft) > 1 and np.ptp(soft) < 1e-9:
        return f"yours is constant ({float(soft[0]):.3g} at every soft step)"
    if len(soft) > 1 and np.all(steps > 0):
        return "yours grows with j; it must fall from about 1 at j = d toward 0 at j = L"
    if np.allclose(soft, c, atol=1e-6):
        return "yours is c_j itself; W_j = c_j (e^c_j - 1) / (e - 1) (the exponential decay)"
    if len(soft) > 2 and np.allclose(steps, steps[0], atol=1e-9):
        return "yours falls linearly; the decay is exponential, c_j (e^c_j - 1) / (e - 1)"
    j = int(np.argmax(~np.isclose(soft, ref, atol=1e-9)))
    return f"first wrong at j = {d + j}: expected {ref[j]:.6g}, got {soft[j]:.6g}"


def test_weights_shape_and_frozen_prefix(student):
    for n, d, L in ((12, 3, 9), (8, 0, 8), (5, 5, 7), (6, 2, 1)):
        w = _weights(student, n, d, L)
        assert np.issubdtype(w.dtype, np.floating), f"W must hold floats, got {w.dtype}"
        assert np.all(w[:d] == 1.0), f"d = {d}: W_j = 1 for the frozen steps j < d, got W[:d] = {_fmt(w[:d])}"


@pytest.mark.parametrize("n,d,L", [(12, 3, 9), (15, 1, 7), (10, 0, 10), (16, 4, 15)])
def test_soft_weights_decay_exponentially(student, n, d, L):
    w, ref = _weights(student, n, d, L), reference_weights(n, d, L)
    soft, want = w[d:L], ref[d:L]
    assert np.allclose(soft, want, rtol=0, atol=1e-9), (
        f"n = {n}, d = {d}, L = {L}: W_j in the soft region d <= j < L should decay as c_j (e^c_j - 1) / (e - 1), "
        f"c_j = (L - j) / (L - d + 1); {_soft_diagnosis(soft, want, d, L)}. Expected {_fmt(want)}, yours {_fmt(soft)}")


def test_weights_zero_past_the_overlap(student):
    for n, d, L in ((12, 3, 9), (8, 0, 5), (5, 4, 2), (6, 3, 3)):
        w = _weights(student, n, d, L)
        free = w[max(L, d):]
        assert np.all(free == 0.0), (f"n = {n}, d = {d}, L = {L}: W_j = 0 for j >= max(L, d) (the previous chunk "
                                     f"has ended), got {_fmt(free)}")
        if L <= d:  # no soft region: the frozen prefix, then zeros
            np.testing.assert_array_equal(w, (np.arange(n) < d).astype(float),
                                          err_msg=f"n = {n}, d = {d}, L = {L} <= d: only the frozen prefix is 1")


def test_hard_schedule_freezes_only(student):
    for n, d, L in ((12, 3, 9), (8, 0, 8), (7, 5, 7)):
        w = _weights(student, n, d, L, "hard")
        np.testing.assert_array_equal(w, (np.arange(n) < d).astype(float),
                                      err_msg=f"schedule 'hard', d = {d}, L = {L}: 1 for j < d, 0 elsewhere (no soft region)")


# ------------------------------------------------------------------------------ the guidance
def _problem(seed: int, b: int = 2, steps: int = 6, dim: int = 2, t: float = 0.6):
    """A seeded iterate x, target Y, mixing matrix M (float64) and weights W for the toy head."""
    g = torch.Generator().manual_seed(seed)
    n = steps * dim
    m = torch.randn(n, n, generator=g, dtype=torch.float64) / math.sqrt(n)
    x = torch.randn(b, steps, dim, generator=g, dtype=torch.float64)
    y = torch.randn(b, steps, dim, generator=g, dtype=torch.float64)
    w = torch.as_tensor(reference_weights(steps, 2, steps - 1))
    return m, t, x, y, w


def reference_guidance(m, t, x, y, w) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(x0_hat, v, g = J^T W (Y - x0_hat)) with the full Jacobian J = d x0_hat / d x, per sample."""
    clean = toy_clean_estimate(m, t)
    x0, v = clean(x)
    err = (y - x0) * w.view(1, -1, 1)
    g = torch.zeros_like(x)
    for i in range(x.shape[0]):
        jac = torch.autograd.functional.jacobian(lambda z: clean(z[None])[0][0], x[i])  # (T, D, T, D)
        g[i] = torch.einsum("td,tdse->se", err[i], jac)
    return x0, v, g


def _student_guidance(student, sandbox, m, t, x, y, w):
    result = student.guidance_vjp(sandbox.new(FACTORY, m, t), x, y, w)
    assert isinstance(result, (tuple, list)) and len(result) == 3, \
        f"guidance_vjp must return (x0_hat, model_output, g), got {type(result).__name__}"
    x0, out, g = result
    assert torch.is_tensor(g) and tuple(g.shape) == tuple(x.shape), \
        f"g must be a tensor of the iterate's shape {tuple(x.shape)}, got {tuple(getattr(g, 'shape', ()))}"
    return x0, out, g


def _guidance_diagnosis(g, m, t, x, y, w) -> str:
    """Which wrong formula ``g`` matches, in words ("" if none of them)."""
    x0, _, ref = reference_guidance(m, t, x, y, w)
    _, _, unweighted = reference_guidance(m, t, x, y, torch.ones_like(w))
    candidates = [
        (-ref, "g has the wrong sign: it is -J^T W (Y - x0_hat), which pushes x0_hat away from the previous chunk Y"),
        (unweighted, "g ignores W: the error must be weighted, e = W (Y - x0_hat)"),
        (unweighted * w.view(1, -1, 1), "W multiplies g after the VJP; it weights the ERROR before it (J mixes the steps)"),
        ((y - x0) * w.view(1, -1, 1), "g is the weighted error itself; carry it back through the network: J^T e"),
    ]
    if x.shape[1] == x.shape[2]:
        err = (y - x0) * w.view(1, 1, -1)
        clean = toy_clean_estimate(m, t)
        z = x.clone().requires_grad_(True)
        (wrong_axis,) = torch.autograd.grad(clean(z)[0], z, grad_outputs=err)
        candidates.append((wrong_axis, "W multiplies the action dimensions; W_j weights step j: weights.view(1, -1, 1)"))
    for value, words in candidates:
        if torch.allclose(g, value, rtol=1e-5, atol=1e-8):
            return words
    return ""


@pytest.mark.parametrize("seed", [0, 1])
def test_vjp_is_jacobian_transpose_times_weighted_error(student, sandbox, seed):
    m, t, x, y, w = _problem(seed)
    x0_ref, v_ref, g_ref = reference_guidance(m, t, x, y, w)
    x0, out, g = _student_guidance(student, sandbox, m, t, x, y, w)
    assert_close(x0, x0_ref, msg=lambda e: f"x0_hat must be clean_fn(x)[0], unchanged: {e}")
    assert_close(out, v_ref, msg=lambda e: f"the model output must be clean_fn(x)[1], unchanged: {e}")
    if not torch.allclose(g, g_ref, rtol=1e-5, atol=1e-8):
        why = _guidance_diagnosis(g, m, t, x, y, w) or "g differs from J^T W (Y - x0_hat)"
        err = float((g - g_ref).abs().max())
        raise AssertionError(f"seed {seed}: {why} (largest error {err:.3g})")


def test_vjp_weights_each_step_of_the_error(student, sandbox):
    m, t, x, y, _ = _problem(2, b=3, steps=4, dim=4)  # T = Da: W on the wrong axis gives no error, only wrong values
    for w in (torch.tensor([1.0, 0.6, 0.2, 0.0], dtype=torch.float64), torch.tensor([0.0, 0.0, 1.0, 0.0], dtype=torch.float64)):
        _, _, g_ref = reference_guidance(m, t, x, y, w)
        _, _, g = _student_guidance(student, sandbox, m, t, x, y, w)
        if not torch.allclose(g, g_ref, rtol=1e-5, atol=1e-8):
            why = _guidance_diagnosis(g, m, t, x, y, w) or "g differs from J^T W (Y - x0_hat)"
            raise AssertionError(f"W = {w.tolist()}: {why}")
    _, _, g = _student_guidance(student, sandbox, m, t, x, y, torch.zeros(4, dtype=torch.float64))
    assert torch.count_nonzero(g) == 0, "with W = 0 everywhere there is nothing to agree with: g must be 0"


def _weighted_error(m, t, x, y, w) -> float:
    x0, _ = toy_clean_estimate(m, t)(x)
    return float((w.view(1, -1, 1) * (y - x0) ** 2).sum())


def test_vjp_pulls_toward_the_previous_chunk(student, sandbox):
    for seed in (3, 4):
        m, t, x, y, w = _problem(seed)
        _, _, g_ref = reference_guidance(m, t, x, y, w)
        _, _, g = _student_guidance(student, sandbox, m, t, x, y, w)
        pull = float((g * g_ref).sum())  # the weighted error's slope along g is -2 <g, g_ref>
        eps = 1e-2 / max(float(g.norm()), 1e-12)
        before, after = _weighted_error(m, t, x, y, w), _weighted_error(m, t, x + eps * g, y, w)
        assert pull > 0, (f"seed {seed}: the guidance {'pushes x0_hat away from' if pull < 0 else 'does not move x0_hat toward'} "
                          f"the previous chunk Y: a small step x + eps g along your g changes the weighted error "
                          f"sum_j W_j |Y_j - x0_hat_j|^2 from {before:.4f} to {after:.4f} (the error is Y - x0_hat)")


# ------------------------------------------------------------------------------ the update
def test_update_closed_form(student):
    gen = torch.Generator().manual_seed(5)
    out, g = torch.randn(2, 6, 2, generator=gen), torch.randn(2, 6, 2, generator=gen)
    for scale in (0.0, 0.7, 5.0):
        got = student.guided_update(out, g, scale)
        assert torch.is_tensor(got) and tuple(got.shape) == (2, 6, 2), \
            f"expected a tensor of shape (2, 6, 2), got {tuple(getattr(got, 'shape', ()))}"
        assert_close(got, out - scale * g, msg=lambda e: f"scale {scale}: out' = out - scale * g: {e}")


def test_update_pulls_toward_the_previous_chunk(student):
    m, t, x, y, w = _problem(6)
    t_next, scale = 0.4, 1.7  # one Euler step t -> t_next (dt < 0) with some guidance weight
    _, v, g_ref = reference_guidance(m, t, x, y, w)
    v_guided = student.guided_update(v, g_ref, scale)
    free, guided = x + (t_next - t) * v, x + (t_next - t) * v_guided
    pull = float(((guided - free) * g_ref).sum())
    e_free, e_guided = _weighted_error(m, t_next, free, y, w), _weighted_error(m, t_next, guided, y, w)
    assert pull > 0, (f"one Euler step t = {t} -> {t_next} with your guided velocity moves the iterate "
                      f"{'against' if pull < 0 else 'not along'} g: the weighted error of x0_hat to the previous "
                      f"chunk Y is {e_guided:.4f} guided vs {e_free:.4f} unguided (v' = v - scale * g)")
