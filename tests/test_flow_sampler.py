"""The ODE sampler of flow matching against closed-form solutions of simple fields."""

from __future__ import annotations

import math

import pytest
import torch

from coursekit.flow.sampler import euler_step, integrate, midpoint_step, time_grid


def _x1(shape=(5, 3)):
    return torch.randn(shape, generator=torch.Generator().manual_seed(0), dtype=torch.float64)


@pytest.mark.parametrize("steps", [1, 2, 3, 10])
@pytest.mark.parametrize("method", ["euler", "midpoint"])
def test_constant_field_is_integrated_exactly(steps, method):
    c = torch.tensor([0.5, -1.0, 2.0], dtype=torch.float64)
    x1 = _x1()
    x0 = integrate(lambda x, t, cond: c.expand_as(x), x1, steps=steps, method=method)
    torch.testing.assert_close(x0, x1 - c)  # dx/dt = c from t = 1 to 0: x(0) = x(1) - c


def test_euler_error_on_a_time_linear_field_is_exactly_one_over_2n():
    # dx/dt = t: x(0) = x(1) - 1/2. Euler sums dt * t_i over the left end points:
    # -(1/N) sum_{i<N} (1 - i/N) = -(1/2 + 1/(2N)), an error of exactly 1/(2N).
    x1 = _x1()
    for n in (1, 2, 4, 8, 16):
        x0 = integrate(lambda x, t, cond: t[:, None].expand_as(x), x1, steps=n)
        torch.testing.assert_close(x0, x1 - 0.5 - 1.0 / (2 * n))
        # the midpoint rule is exact for a field linear in t
        xm = integrate(lambda x, t, cond: t[:, None].expand_as(x), x1, steps=n, method="midpoint")
        torch.testing.assert_close(xm, x1 - 0.5)


def test_euler_is_first_order_and_midpoint_second_order_on_a_linear_field():
    # dx/dt = x from t = 1 down to 0: x(0) = x(1) * exp(-1).
    x1 = _x1()
    exact = x1 * math.exp(-1.0)
    errs = {m: [float((integrate(lambda x, t, cond: x, x1, steps=n, method=m) - exact).abs().max())
                for n in (8, 16, 32, 64)] for m in ("euler", "midpoint")}
    for m, order in (("euler", 1), ("midpoint", 2)):
        ratios = [a / b for a, b in zip(errs[m][:-1], errs[m][1:])]
        for r in ratios:  # doubling N divides the error by 2^order
            assert abs(r - 2 ** order) < 0.15 * 2 ** order, (m, errs[m], ratios)
    # and Euler's iterate is the closed form x1 (1 - 1/N)^N
    for n in (1, 3, 7):
        torch.testing.assert_close(integrate(lambda x, t, cond: x, x1, steps=n), x1 * (1 - 1 / n) ** n)


def test_steps_pass_time_as_a_batch_vector_and_cond_unchanged():
    seen = []
    cond = object()

    def v(x, t, c):
        assert c is cond
        assert t.shape == (x.shape[0],) and t.dtype == x.dtype
        seen.append(float(t[0]))
        return torch.zeros_like(x)

    integrate(v, _x1(), cond, steps=4)
    assert seen == pytest.approx([1.0, 0.75, 0.5, 0.25])
    seen.clear()
    integrate(v, _x1(), cond, steps=2, method="midpoint")
    assert seen == pytest.approx([1.0, 0.75, 0.5, 0.25])  # t, then t + dt/2, per step


def test_trajectory_and_custom_step_fn():
    x1 = _x1()
    x0, path = integrate(lambda x, t, c: x, x1, steps=5, return_trajectory=True)
    assert path.shape == (6, *x1.shape)
    torch.testing.assert_close(path[0], x1)
    torch.testing.assert_close(path[-1], x0)
    calls = []

    def my_step(model, x, t, dt, cond):
        calls.append((t, dt))
        return euler_step(model, x, t, dt, cond)

    torch.testing.assert_close(integrate(lambda x, t, c: x, x1, steps=5, step_fn=my_step), x0)
    assert len(calls) == 5 and all(dt == pytest.approx(-0.2) for _, dt in calls)
    torch.testing.assert_close(midpoint_step(lambda x, t, c: x, x1, 1.0, -0.5, None), x1 * (1 - 0.5 + 0.125))


def test_bad_arguments_are_refused_with_the_value():
    with pytest.raises(ValueError, match="steps must be a positive int, got 0"):
        time_grid(0)
    with pytest.raises(ValueError, match="'rk4'"):
        integrate(lambda x, t, c: x, _x1(), method="rk4")
    assert time_grid(3)[0] == 1.0 and time_grid(3)[-1] == 0.0
