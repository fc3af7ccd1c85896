"""Sampling a flow: integrate dx/dt = v_theta(x, t, o) from noise (t = 1) to data (t = 0).

With N steps the time grid is t_i = 1 - i / N, i = 0..N, and every step has dt = -1 / N
(negative: time runs toward the data). pi0 uses N = 10 Euler steps (Black et al. 2024).

    Euler (first order, one network call per step):
        x_{t+dt} = x_t + dt * v(x_t, t)
    Midpoint (second order, two calls per step):
        x_mid    = x_t + dt/2 * v(x_t, t)
        x_{t+dt} = x_t + dt * v(x_mid, t + dt/2)

Global error after integrating to t = 0 is O(1/N) for Euler and O(1/N^2) for midpoint on a
smooth field (tests/test_flow_sampler.py checks both orders on a linear field). With the exact
velocity of a straight path one Euler step is already exact. But the field a network learns is
the MARGINAL one, the average of e - a0 over every pair whose path passes through (x, t)
(coursekit/flow/loss.py), and its paths curve whenever p(a0 | o) is not a single point: one
mode with any spread is enough (Gaussian data of std s > 0 already bends them), several modes
bend them more. One step lands on E[a0 | o]; extra steps follow the curve.

``euler_step`` is exercise "euler_step" (10.2); ``integrate`` takes the step function as an
argument, so a student's step plugs straight into the policy's sampler.
"""

from __future__ import annotations

from typing import Any, Callable

import torch

VelocityModel = Callable[[torch.Tensor, torch.Tensor, Any], torch.Tensor]
StepFn = Callable[[VelocityModel, torch.Tensor, float, float, Any], torch.Tensor]

METHODS = ("euler", "midpoint")


def euler_step(velocity_model: VelocityModel, x_t: torch.Tensor, t: float, dt: float, cond: Any) -> torch.Tensor:
    """One explicit Euler step of dx/dt = v(x, t, cond): x_{t+dt} = x_t + dt * v(x_t, t, cond).

    Args:
        velocity_model: callable ``(x (B, ...), t (B,) float, cond) -> v (B, ...)``; it gets the
            current time as a (B,) tensor of x_t's dtype and device, every entry equal to t.
        x_t: current sample, (B, ...).
        t: current time (a Python float; 1 = noise, 0 = data).
        dt: step in time (negative when integrating from noise to data, e.g. -1/N).
        cond: conditioning passed to ``velocity_model`` unchanged.

    Returns:
        x_{t+dt}, same shape as x_t.
    """
    # BEGIN SOLUTION
    t_vec = torch.full((x_t.shape[0],), float(t), dtype=x_t.dtype, device=x_t.device)  # (B,)
    x_next = x_t + dt * velocity_model(x_t, t_vec, cond)
    # END SOLUTION
    return x_next


def midpoint_step(velocity_model: VelocityModel, x_t: torch.Tensor, t: float, dt: float, cond: Any) -> torch.Tensor:
    """One explicit midpoint (RK2) step: half an Euler step, then the full step with the midpoint's velocity."""
    b = x_t.shape[0]
    t0 = torch.full((b,), float(t), dtype=x_t.dtype, device=x_t.device)  # (B,)
    x_mid = x_t + 0.5 * dt * velocity_model(x_t, t0, cond)
    t_mid = torch.full((b,), float(t) + 0.5 * dt, dtype=x_t.dtype, device=x_t.device)  # (B,)
    return x_t + dt * velocity_model(x_mid, t_mid, cond)


def time_grid(steps: int) -> list[float]:
    """t_i = 1 - i / steps for i = 0..steps (from noise to data), exact at both ends."""
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 1:
        raise ValueError(f"steps must be a positive int, got {steps!r}")
    return [1.0 - i / steps for i in range(steps + 1)]


def integrate(velocity_model: VelocityModel, x1: torch.Tensor, cond: Any = None, steps: int = 10,
              method: str = "euler", step_fn: StepFn | None = None,
              return_trajectory: bool = False) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """Integrate from x1 (the noise, t = 1) to t = 0 in ``steps`` uniform steps.

    Args:
        velocity_model: ``(x (B, ...), t (B,), cond) -> v (B, ...)``.
        x1: starting noise, (B, ...).
        cond: passed to every call unchanged.
        steps: N, number of steps (Euler: N network calls; midpoint: 2N).
        method: "euler" or "midpoint" (ignored when ``step_fn`` is given).
        step_fn: ``(velocity_model, x_t, t, dt, cond) -> x_{t+dt}``, e.g. a student's ``euler_step``.
        return_trajectory: also return every iterate, (N+1, B, ...), x1 first.

    Returns:
        x0 (B, ...), or (x0, trajectory).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    step = step_fn or (euler_step if method == "euler" else midpoint_step)
    grid = time_grid(steps)
    x = x1
    path = [x]
    for t, t_next in zip(grid[:-1], grid[1:]):
        x = step(velocity_model, x, t, t_next - t, cond)
        if return_trajectory:
            path.append(x)
    if return_trajectory:
        return x, torch.stack(path)  # (N+1, B, ...)
    return x
