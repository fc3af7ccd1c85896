"""The noise-prediction (epsilon) loss of DDPM, on action chunks.

Training a diffusion model reduces to regression (Ho et al. 2020, eq. 14, "L_simple"): noise a clean
chunk to a random step t in closed form, ``a_t = sqrt(abar_t) a_0 + sqrt(1 - abar_t) eps``, and ask the
network to predict the noise eps from ``(a_t, t, o)``. Diffusion Policy (Chi et al. 2023, eq. 5) uses
exactly this loss with the observation features o as conditioning.

``q_sample`` and ``epsilon_loss`` are exercise "noise_loss"; ``diffusion_loss`` draws t and eps and
takes the loss function as an argument, so a student's ``epsilon_loss`` plugs straight in.
"""

from __future__ import annotations

from typing import Any, Callable

import torch
import torch.nn.functional as F

from coursekit.diffusion.schedules import NoiseSchedule

EpsModel = Callable[[torch.Tensor, torch.Tensor, Any], torch.Tensor]


def q_sample(x0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor,
             alphas_cumprod: torch.Tensor) -> torch.Tensor:
    """Noise clean samples to step t in one shot (Ho et al. 2020, eq. 4, reparametrised).

        x_t = sqrt(abar_t) * x0 + sqrt(1 - abar_t) * noise

    Args:
        x0: clean samples, (B, ...) — e.g. normalised action chunks (B, Tp, Da).
        t: integer timesteps, (B,) long, each in [0, T).
        noise: standard normal noise eps, same shape as x0.
        alphas_cumprod: abar, (T,) (``NoiseSchedule.alphas_cumprod``).

    Returns:
        x_t, same shape as x0. ``abar_t`` is picked per sample and broadcast over the other dims.
    """
    if x0.shape != noise.shape:
        raise ValueError(f"noise shape {tuple(noise.shape)} must equal x0 shape {tuple(x0.shape)}")
    if t.shape != x0.shape[:1]:
        raise ValueError(f"t must have shape ({x0.shape[0]},) (one timestep per sample), got {tuple(t.shape)}")
    # BEGIN SOLUTION
    abar = alphas_cumprod.to(device=x0.device, dtype=x0.dtype)[t]  # (B,)
    abar = abar.reshape(-1, *([1] * (x0.ndim - 1)))  # (B, 1, ..., 1)
    x_t = abar.sqrt() * x0 + (1.0 - abar).sqrt() * noise
    # END SOLUTION
    return x_t


def epsilon_loss(eps_model: EpsModel, x0: torch.Tensor, cond: Any, t: torch.Tensor, noise: torch.Tensor,
                 alphas_cumprod: torch.Tensor,
                 q_sample_fn: Callable[..., torch.Tensor] = q_sample) -> torch.Tensor:
    """The epsilon-prediction loss for given timesteps and noise (Ho et al. 2020, eq. 14).

        loss = mean over all elements of (eps_model(x_t, t, cond) - noise)^2,
        x_t = q_sample_fn(x0, t, noise, alphas_cumprod)

    Args:
        eps_model: callable ``(x_t (B, ...), t (B,) long, cond) -> eps_hat (B, ...)``.
        x0: clean samples, (B, ...).
        cond: conditioning passed through to ``eps_model`` unchanged (e.g. (B, cond_dim) or None).
        t: timesteps, (B,) long in [0, T).
        noise: the noise added, same shape as x0 — the regression target.
        alphas_cumprod: abar, (T,).
        q_sample_fn: the forward-noising function (defaults to this module's ``q_sample``).

    Returns:
        The scalar mean squared error (a 0-d tensor that backpropagates into ``eps_model``).
    """
    # BEGIN SOLUTION
    x_t = q_sample_fn(x0, t, noise, alphas_cumprod)
    eps_hat = eps_model(x_t, t, cond)
    loss = F.mse_loss(eps_hat, noise)
    # END SOLUTION
    return loss


def diffusion_loss(eps_model: EpsModel, x0: torch.Tensor, cond: Any, schedule: NoiseSchedule,
                   generator: torch.Generator | None = None,
                   loss_fn: Callable[..., torch.Tensor] = epsilon_loss) -> torch.Tensor:
    """One Monte-Carlo sample of the training loss: draw t ~ U{0..T-1} and eps ~ N(0, I) per sample.

    Args:
        eps_model: ``(x_t, t, cond) -> eps_hat`` (e.g. ``ConditionalUnet1D``).
        x0: clean (normalised) samples, (B, ...).
        cond: passed to ``eps_model`` unchanged.
        schedule: the ``NoiseSchedule`` (supplies T and abar).
        generator: torch.Generator for t and eps (drawn on its device, then moved to x0's device);
            None uses torch's global generator.
        loss_fn: ``(eps_model, x0, cond, t, noise, alphas_cumprod) -> scalar`` — the library's
            ``epsilon_loss`` or a student's.

    Returns:
        Scalar loss.
    """
    if not torch.is_tensor(x0) or x0.ndim < 2:
        raise ValueError(f"x0 must be a tensor of shape (B, ...), got {type(x0).__name__} "
                         f"with shape {tuple(getattr(x0, 'shape', ()))}")
    if not torch.isfinite(x0).all():
        raise ValueError("x0 contains NaN or inf; check the batch and its normalisation")
    gen_device = generator.device if generator is not None else x0.device
    B = x0.shape[0]
    t = torch.randint(0, schedule.num_train_timesteps, (B,), generator=generator, device=gen_device)
    noise = torch.randn(x0.shape, generator=generator, device=gen_device, dtype=x0.dtype)
    return loss_fn(eps_model, x0, cond, t.to(x0.device), noise.to(x0.device),
                   schedule.alphas_cumprod.to(x0.device))
