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


def _diffusers_ddim(n):
    diffusers = pytest.importorskip("diffusers")
    ref = diffusers.DDIMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", clip_sample=True,
                                  prediction_type="epsilon", set_alpha_to_one=True, steps_offset=0)
    ref.set_timesteps(n)
    return ref


def test_deterministic_step_closed_form(student):
    g = torch.Generator().manual_seed(0)
    x_t, eps = torch.randn(SHAPE, generator=g) * 0.5, torch.randn(SHAPE, generator=g)
    a_t, a_prev = 0.3, 0.7
    got = student.ddim_step(eps, x_t, a_t, a_prev, eta=0.0, noise=None, clip_sample=False)
    x0 = (x_t - math.sqrt(1 - a_t) * eps) / math.sqrt(a_t)
    want = math.sqrt(a_prev) * x0 + math.sqrt(1 - a_prev) * eps
    assert got.shape == SHAPE, f"shape {tuple(got.shape)}, expected {SHAPE}"
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5,
                               msg=lambda m: f"eta = 0: x_prev = sqrt(abar_prev) x0_hat + sqrt(1 - abar_prev) eps: {m}")


def test_clip_sample_clamps_x0_hat(student):
    g = torch.Generator().manual_seed(1)
    x_t, eps = torch.randn(SHAPE, generator=g) * 4, torch.randn(SHAPE, generator=g)
    a_t, a_prev = 0.5, 0.9
    got = student.ddim_step(eps, x_t, a_t, a_prev, eta=0.0, noise=None, clip_sample=True, clip_sample_range=1.0)
    x0 = ((x_t - math.sqrt(1 - a_t) * eps) / math.sqrt(a_t)).clamp(-1, 1)
    want = math.sqrt(a_prev) * x0 + math.sqrt(1 - a_prev) * eps  # the model's eps, not re-derived
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5,
                               msg=lambda m: f"clamp x0_hat to [-r, r] when clip_sample; keep eps as given: {m}")


def test_stochastic_step_closed_form(student):
    g = torch.Generator().manual_seed(2)
    x_t, eps, noise = (torch.randn(SHAPE, generator=g) for _ in range(3))
    a_t, a_prev, eta = 0.2, 0.6, 0.7
    got = student.ddim_step(eps, x_t, a_t, a_prev, eta=eta, noise=noise, clip_sample=False)
    sigma = eta * math.sqrt((1 - a_prev) / (1 - a_t) * (1 - a_t / a_prev))
    x0 = (x_t - math.sqrt(1 - a_t) * eps) / math.sqrt(a_t)
    want = math.sqrt(a_prev) * x0 + math.sqrt(1 - a_prev - sigma ** 2) * eps + sigma * noise
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5,
                               msg=lambda m: f"eta > 0: sigma = eta sqrt((1-abar_prev)/(1-abar_t) (1-abar_t/abar_prev)): {m}")


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
    want = ((x_t - math.sqrt(1 - a_t) * eps) / math.sqrt(a_t)).clamp(-1, 1)
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)
    assert torch.isfinite(got).all()
