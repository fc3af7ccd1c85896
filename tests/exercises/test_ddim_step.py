"""Exercise 4.1 (ddim_step): one DDIM update. References: diffusers' DDIMScheduler, the closed form."""

from __future__ import annotations

import math

import pytest
import torch

from coursekit.diffusion.samplers import DDIMSampler
from coursekit.diffusion.schedules import NoiseSchedule

EXERCISE = "ddim_step"

SCHEDULE = NoiseSchedule(num_train_timesteps=100)
SHAPE = (3, 16, 2)


def _eps_model(x, t, cond):
    return torch.tanh(x) * 0.8 + 0.3 * torch.sin(t.float()[:, None, None] / 7.0 + x)


def _ddim(x_t, eps, a_t, a_prev, eta=0.0, noise=None, clip=None, mistake=""):
    """The closed form (Song et al. 2021, eq. 12), or a named common mistake of it."""
    r = math.sqrt
    x0 = (x_t - r(1 - a_t) * eps) if mistake == "x0_hat not divided by sqrt(abar_t)" else (x_t - r(1 - a_t) * eps) / r(a_t)
    if clip is not None and mistake != "x0_hat not clipped":
        x0 = x0.clamp(-clip, clip)
    sigma = eta * r((1 - a_prev) / (1 - a_t) * (1 - a_t / a_prev)) if a_prev < 1 else 0.0
    keep = 1 - a_prev if mistake == "sigma^2 not taken out of the direction term" else 1 - a_prev - sigma ** 2
    scale = r(1 - a_t) if mistake == "direction term uses sqrt(1 - abar_t) instead of sqrt(1 - abar_prev)" else r(max(keep, 0.0))
    out = r(a_prev) * x0 + scale * eps
    if noise is not None and mistake != "the sigma * noise term is missing":
        out = out + sigma * noise
    return out


MISTAKES = ("x0_hat not divided by sqrt(abar_t)", "x0_hat not clipped", "direction term uses sqrt(1 - abar_t) instead "
            "of sqrt(1 - abar_prev)", "sigma^2 not taken out of the direction term", "the sigma * noise term is missing")


def _check(got, x_t, eps, a_t, a_prev, what, **kw):
    """Compare x_prev with the closed form; on a mismatch name the quantity that went wrong."""
    want = _ddim(x_t, eps, a_t, a_prev, **kw)
    assert tuple(got.shape) == tuple(want.shape), f"x_prev has shape {tuple(got.shape)}, expected {tuple(want.shape)} (same as x_t)"
    if torch.allclose(got, want, rtol=1e-5, atol=1e-5):
        return
    for mistake in MISTAKES:
        if torch.allclose(got, _ddim(x_t, eps, a_t, a_prev, mistake=mistake, **kw), rtol=1e-5, atol=1e-5):
            raise AssertionError(f"{what}: x_prev differs from the closed form; it matches the update with {mistake}")
    x0_only = torch.allclose(got, _ddim(x_t, eps, a_t, 1.0, clip=kw.get("clip")), rtol=1e-5, atol=1e-5)
    raise AssertionError(f"{what}: x_prev differs from the closed form (max error {float((got - want).abs().max()):.3g})"
                         + ("; it equals x0_hat: the sqrt(abar_prev) x0_hat + direction step is missing" if x0_only else ""))


def _diffusers_ddim(n):
    diffusers = pytest.importorskip("diffusers")
    ref = diffusers.DDIMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", clip_sample=True,
                                  prediction_type="epsilon", set_alpha_to_one=True, steps_offset=0)
    ref.set_timesteps(n)
    return ref


def test_deterministic_step_closed_form(student):
    g = torch.Generator().manual_seed(0)
    x_t, eps = torch.randn(SHAPE, generator=g) * 0.5, torch.randn(SHAPE, generator=g)
    got = student.ddim_step(eps, x_t, 0.3, 0.7, eta=0.0, noise=None, clip_sample=False)
    _check(got, x_t, eps, 0.3, 0.7, "eta = 0, no clipping")


def test_clip_sample_clamps_x0_hat(student):
    g = torch.Generator().manual_seed(1)
    x_t, eps = torch.randn(SHAPE, generator=g) * 4, torch.randn(SHAPE, generator=g)
    got = student.ddim_step(eps, x_t, 0.5, 0.9, eta=0.0, noise=None, clip_sample=True, clip_sample_range=1.0)
    _check(got, x_t, eps, 0.5, 0.9, "clip_sample=True, range 1 (the direction term keeps the model's eps)", clip=1.0)


def test_stochastic_step_closed_form(student):
    g = torch.Generator().manual_seed(2)
    x_t, eps, noise = (torch.randn(SHAPE, generator=g) for _ in range(3))
    got = student.ddim_step(eps, x_t, 0.2, 0.6, eta=0.7, noise=noise, clip_sample=False)
    _check(got, x_t, eps, 0.2, 0.6, "eta = 0.7 with the given noise", eta=0.7, noise=noise)


@pytest.mark.parametrize("n,eta", [(10, 0.0), (4, 0.0), (10, 1.0)])
def test_matches_diffusers_step_for_step(student, n, eta):
    ref = _diffusers_ddim(n)
    ours = DDIMSampler(SCHEDULE, num_inference_steps=n, eta=eta, step_fn=student.ddim_step)
    x_ref = torch.randn(SHAPE, generator=torch.Generator().manual_seed(3))
    x = x_ref.clone()
    g_ours, g_ref = torch.Generator().manual_seed(4), torch.Generator().manual_seed(4)
    for t in ref.timesteps.tolist():
        tb = torch.full((SHAPE[0],), t, dtype=torch.long)
        x_ref = ref.step(_eps_model(x_ref, tb, None), t, x_ref, eta=eta, generator=g_ref).prev_sample
        x = ours.step(_eps_model(x, tb, None), t, x, generator=g_ours)
        torch.testing.assert_close(x, x_ref, rtol=1e-5, atol=1e-5,
                                   msg=lambda m: f"{n}-step DDIM (eta={eta}) differs from diffusers at t={t}: {m}")


def test_last_step_returns_clean_estimate(student):
    # Past the last step abar_prev = 1: x_prev is exactly the (clipped) x0 estimate.
    g = torch.Generator().manual_seed(5)
    x_t, eps = torch.randn(SHAPE, generator=g), torch.randn(SHAPE, generator=g)
    a_t = float(SCHEDULE.alphas_cumprod[0])
    got = student.ddim_step(eps, x_t, a_t, 1.0, eta=0.0, noise=None, clip_sample=True)
    assert torch.isfinite(got).all(), "x_prev is not finite with abar_prev = 1 (a division by 1 - abar_prev?)"
    _check(got, x_t, eps, a_t, 1.0, "abar_prev = 1 (the last step): x_prev must be the clipped x0_hat", clip=1.0)
