"""Noise schedules against their closed forms and against diffusers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from coursekit.diffusion import NoiseSchedule, cosine_alpha_bar


def test_cosine_alpha_bar_matches_closed_form():
    T, s = 100, 0.008
    sched = NoiseSchedule(num_train_timesteps=T)
    t = np.arange(1, T + 1)
    f = np.cos((t / T + s) / (1 + s) * math.pi / 2) ** 2
    f0 = math.cos(s / (1 + s) * math.pi / 2) ** 2
    expected = f / f0  # Nichol & Dhariwal eq. 17; the beta cap binds only at the very last step
    np.testing.assert_allclose(sched.alphas_cumprod[:-1].numpy(), expected[:-1], rtol=1e-5, atol=1e-7)
    assert sched.betas.max().item() == pytest.approx(0.999, abs=1e-6)  # the cap at t = T-1
    assert float(cosine_alpha_bar(0.5)) == pytest.approx(math.cos((0.5 + s) / (1 + s) * math.pi / 2) ** 2)


def test_linear_schedule_closed_form():
    sched = NoiseSchedule(num_train_timesteps=50, beta_schedule="linear", beta_start=1e-4, beta_end=0.02)
    betas = np.linspace(1e-4, 0.02, 50)
    np.testing.assert_allclose(sched.betas.numpy(), betas, rtol=1e-6)
    np.testing.assert_allclose(sched.alphas.numpy(), 1 - betas, rtol=1e-6)
    np.testing.assert_allclose(sched.alphas_cumprod.numpy(), np.cumprod(1 - betas), rtol=1e-5)


@pytest.mark.parametrize("beta_schedule", ["squaredcos_cap_v2", "linear"])
def test_schedule_matches_diffusers(beta_schedule):
    diffusers = pytest.importorskip("diffusers")
    ref = diffusers.DDPMScheduler(num_train_timesteps=100, beta_schedule=beta_schedule)
    ours = NoiseSchedule(num_train_timesteps=100, beta_schedule=beta_schedule)
    torch.testing.assert_close(ours.betas, ref.betas, atol=1e-6, rtol=1e-5)
    torch.testing.assert_close(ours.alphas_cumprod, ref.alphas_cumprod, atol=1e-6, rtol=1e-5)


def test_schedule_properties():
    sched = NoiseSchedule()
    assert sched.betas.shape == sched.alphas.shape == sched.alphas_cumprod.shape == (100,)
    assert sched.betas.dtype == torch.float32
    abar = sched.alphas_cumprod
    assert (abar[1:] < abar[:-1]).all() and 0 < abar[-1] < 1e-3 and abar[0] > 0.99
    assert (sched.snr()[1:] < sched.snr()[:-1]).all()


@pytest.mark.parametrize("kwargs,match", [
    ({"num_train_timesteps": 0}, "num_train_timesteps"),
    ({"beta_schedule": "cosine"}, "'cosine'"),
    ({"beta_schedule": "linear", "beta_start": 0.1, "beta_end": 0.01}, "beta_start=0.1"),
    ({"max_beta": 1.5}, "1.5"),
])
def test_bad_config_raises_and_shows_value(kwargs, match):
    with pytest.raises(ValueError, match=match):
        NoiseSchedule(**kwargs)
