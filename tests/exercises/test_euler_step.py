"""Exercise 10.2 (euler_step): one Euler step of dx/dt = v(x, t, cond). References: closed-form ODE solutions."""

from __future__ import annotations

import pytest
import torch

from coursekit.grading.compare import assert_close

EXERCISE = "euler_step"

SHAPE = (3, 16, 2)


def _x(seed=0, dtype=torch.float32):
    return torch.randn(SHAPE, generator=torch.Generator().manual_seed(seed), dtype=dtype)


def _model(x, t, cond):
    return torch.tanh(x) * 0.8 + cond * t[:, None, None]


def test_step_closed_form(student):
    x = _x(1)
    for t, dt in ((1.0, -0.25), (0.4, -0.1), (0.5, 0.5)):
        got = student.euler_step(_model, x, t, dt, 0.3)
        want = x + dt * (torch.tanh(x) * 0.8 + 0.3 * t)
        assert got.shape == SHAPE, f"shape {tuple(got.shape)}, expected {SHAPE}"
        assert_close(got, want, rtol=1e-5, atol=1e-6,
                                   msg=lambda m: f"t={t}, dt={dt}: x_next = x_t + dt * v(x_t, t, cond): {m}")


def test_model_gets_time_as_a_batch_vector(student):
    seen = {}

    def model(x, t, cond):
        seen["t"], seen["cond"] = t, cond
        return torch.zeros_like(x)

    cond = torch.randn(SHAPE[0], 4, generator=torch.Generator().manual_seed(9))
    for dtype in (torch.float32, torch.float64):
        student.euler_step(model, _x(2, dtype), 0.75, -0.25, cond)
        t = seen.get("t")
        assert torch.is_tensor(t) and t.shape == (SHAPE[0],), \
            f"pass the time as a (B,) = ({SHAPE[0]},) tensor, got {t!r}"
        assert t.dtype == dtype, f"time tensor dtype {t.dtype}, expected x_t's {dtype}"
        assert torch.all(t == 0.75), "every entry of the time vector is the current t"
        assert seen["cond"] is not None and torch.equal(seen["cond"], cond), "pass cond to the model unchanged"


def _run(student, v, x1, n):
    x = x1
    for i in range(n):
        x = student.euler_step(v, x, 1.0 - i / n, -1.0 / n, None)
    return x


@pytest.mark.parametrize("n", [1, 3, 8])
def test_exact_on_a_constant_field(student, n):
    c = torch.tensor([0.5, -1.5], dtype=torch.float64)
    x1 = _x(3, torch.float64)
    assert_close(_run(student, lambda x, t, cond: c.expand_as(x), x1, n), x1 - c,
                               msg=lambda m: f"{n} steps on v = c must move x by exactly -c: {m}")


def test_first_order_on_a_linear_field(student):
    x1 = _x(4, torch.float64)
    for n in (1, 2, 5, 10):
        assert_close(_run(student, lambda x, t, cond: x, x1, n), x1 * (1 - 1 / n) ** n,
                                   msg=lambda m: f"dx/dt = x, {n} steps: Euler gives x1 (1 - 1/N)^N: {m}")
    exact = x1 * torch.exp(torch.tensor(-1.0, dtype=torch.float64))
    e16 = float((_run(student, lambda x, t, c: x, x1, 16) - exact).abs().max())
    e32 = float((_run(student, lambda x, t, c: x, x1, 32) - exact).abs().max())
    assert 1.8 < e16 / e32 < 2.2, f"doubling the steps should halve the error (first order), ratio {e16 / e32:.2f}"
