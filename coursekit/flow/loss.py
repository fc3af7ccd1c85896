"""The flow-matching objective on action chunks (conditional flow matching / rectified flow).

Pick a data chunk a0, Gaussian noise e and a time t; the straight path between them and its
constant velocity are (pi0's convention: t = 1 noise, t = 0 data; Black et al. 2024)::

    x_t = t * e + (1 - t) * a0          u = e - a0

and the network regresses that velocity (Lipman et al. 2023, eq. 23; Liu et al. 2023, eq. 1)::

    loss = E_{t, e} || v_theta(x_t, t, o) - u ||^2

Both cited papers run time THE OTHER WAY: their t = 0 is noise and t = 1 data, with
x_t = t a0 + (1 - t) e (Lipman et al. with sigma_min = 0) and target a0 - e. Their t is 1 - t
here and their velocity is minus this one: the same straight paths and the same minimiser,
travelled in the opposite direction (hence dt = -1/N in ``coursekit/flow/sampler.py``).

The minimiser is the conditional expectation E[e - a0 | x_t, o]: averaged over every (a0, e)
pair whose path passes through x_t. At t = 1 that is E[e - a0 | e, o] = e - E[a0 | o], so ONE
Euler step of length 1 from noise lands on the conditional mean E[a0 | o] -- the regression
answer of chapter 1. More steps follow the curved marginal paths and keep the modes apart.

Training times: pi0 draws t from Beta(1.5, 1) rescaled into [0.001, 1) (``kind="beta"``, the
default here), whose density 1.5 * sqrt(s) puts more samples at the noisy end. Why: a few-step
sampler spends its longest steps there (1 step queries only t = 1), and that is where the
choice between modes is made; near t = 0 the target e - a0 is nearly determined by x_t and
easy to learn. ``kind="uniform"`` is the other common choice (Lipman et al. 2023). The default
is pi0's, untuned here.

``sample_flow_time`` and ``flow_matching_loss`` are exercise "flow_loss" (10.1); ``flow_loss``
draws t and e and takes the loss function as an argument, so a student's version plugs in.
"""

from __future__ import annotations

from typing import Any, Callable

import torch
import torch.nn.functional as F

VelocityModel = Callable[[torch.Tensor, torch.Tensor, Any], torch.Tensor]

TIME_SAMPLINGS = ("beta", "uniform")
T_MIN = 0.001
"""Smallest training time: pi0 rescales its Beta sample s into t = 0.001 + 0.999 s."""


def sample_flow_time(n: int, kind: str = "beta", generator: torch.Generator | None = None,
                     device: torch.device | str | None = None) -> torch.Tensor:
    """Draw n training times t in [0.001, 1): (n,) float32.

        kind "uniform": s ~ U[0, 1)
        kind "beta":    s ~ Beta(1.5, 1), density 1.5 sqrt(s); its CDF is s^1.5, so s = u^(2/3)
                        with u ~ U[0, 1) (inverse-CDF sampling; torch's Beta takes no generator)
        then           t = 0.001 + 0.999 * s   (pi0's rescaling: never exactly t = 0)

    Args:
        n: number of times (one per chunk in the batch).
        kind: "beta" (pi0, default) or "uniform".
        generator: torch.Generator for u (None: torch's global generator); same generator state,
            same times.
        device: where to create them (default: the generator's device, else CPU).

    Returns:
        t, (n,) float32 in [0.001, 1).
    """
    if kind not in TIME_SAMPLINGS:
        raise ValueError(f"time sampling must be one of {TIME_SAMPLINGS}, got {kind!r}")
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n must be a positive int, got {n!r}")
    device = device if device is not None else (generator.device if generator is not None else "cpu")
    # BEGIN SOLUTION
    u = torch.rand(n, generator=generator, device=device)  # (n,) in [0, 1)
    s = u.pow(2.0 / 3.0) if kind == "beta" else u  # Beta(1.5, 1) by inverse CDF, or uniform
    t = T_MIN + (1.0 - T_MIN) * s
    # END SOLUTION
    return t


def flow_matching_loss(velocity_model: VelocityModel, a0: torch.Tensor, cond: Any, t: torch.Tensor,
                       noise: torch.Tensor) -> torch.Tensor:
    """The flow-matching loss for given times and noise (pi0's convention).

        x_t  = t * noise + (1 - t) * a0        (t broadcast per sample over the chunk)
        u    = noise - a0                      (the path's velocity dx_t/dt, the target)
        loss = mean over all elements of (velocity_model(x_t, t, cond) - u)^2

    Args:
        velocity_model: callable ``(x_t (B, ...), t (B,) float, cond) -> v (B, ...)``.
        a0: clean (normalised) chunks, (B, ...) e.g. (B, Tp, Da).
        cond: conditioning passed to ``velocity_model`` unchanged (e.g. (B, cond_dim) or None).
        t: times, (B,) float in [0, 1]; 1 = pure noise.
        noise: standard normal e, same shape as a0.

    Returns:
        The scalar mean squared error (a 0-d tensor that backpropagates into ``velocity_model``).
    """
    if a0.shape != noise.shape:
        raise ValueError(f"noise shape {tuple(noise.shape)} must equal a0 shape {tuple(a0.shape)}")
    if t.shape != a0.shape[:1]:
        raise ValueError(f"t must have shape ({a0.shape[0]},) (one time per sample), got {tuple(t.shape)}")
    # BEGIN SOLUTION
    tb = t.to(a0.dtype).reshape(-1, *([1] * (a0.ndim - 1)))  # (B, 1, ..., 1)
    x_t = tb * noise + (1.0 - tb) * a0
    target = noise - a0
    loss = F.mse_loss(velocity_model(x_t, t, cond), target)
    # END SOLUTION
    return loss


def flow_loss(velocity_model: VelocityModel, a0: torch.Tensor, cond: Any, time_sampling: str = "beta",
              generator: torch.Generator | None = None,
              loss_fn: Callable[..., torch.Tensor] = flow_matching_loss) -> torch.Tensor:
    """One Monte-Carlo sample of the training loss: draw t (``time_sampling``) and e ~ N(0, I) per sample.

    Args:
        velocity_model: ``(x_t, t, cond) -> v`` (e.g. the flow policy's U-Net wrapper).
        a0: clean (normalised) chunks, (B, ...).
        cond: passed to ``velocity_model`` unchanged.
        time_sampling: "beta" (pi0) or "uniform", see :func:`sample_flow_time`.
        generator: torch.Generator for t and e (drawn on its device, then moved to a0's device).
        loss_fn: ``(velocity_model, a0, cond, t, noise) -> scalar`` -- the library's or a student's.
    """
    if not torch.is_tensor(a0) or a0.ndim < 2:
        raise ValueError(f"a0 must be a tensor of shape (B, ...), got {type(a0).__name__} "
                         f"with shape {tuple(getattr(a0, 'shape', ()))}")
    if not torch.isfinite(a0).all():
        raise ValueError("a0 contains NaN or inf; check the batch and its normalisation")
    gen_device = generator.device if generator is not None else a0.device
    t = sample_flow_time(a0.shape[0], time_sampling, generator=generator, device=gen_device)
    noise = torch.randn(a0.shape, generator=generator, device=gen_device, dtype=a0.dtype)
    return loss_fn(velocity_model, a0, cond, t.to(a0.device), noise.to(a0.device))
