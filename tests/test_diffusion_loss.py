"""The forward process and the epsilon loss against their closed forms."""

from __future__ import annotations

import math

import pytest
import torch

from coursekit.diffusion import NoiseSchedule, diffusion_loss, epsilon_loss, q_sample


def test_q_sample_closed_form_per_sample():
    sched = NoiseSchedule()
    g = torch.Generator().manual_seed(0)
    x0, noise = torch.randn(4, 16, 2, generator=g), torch.randn(4, 16, 2, generator=g)
    t = torch.tensor([0, 10, 50, 99])
    x_t = q_sample(x0, t, noise, sched.alphas_cumprod)
    for i, ti in enumerate(t.tolist()):
        a = float(sched.alphas_cumprod[ti])
        torch.testing.assert_close(x_t[i], math.sqrt(a) * x0[i] + math.sqrt(1 - a) * noise[i])


def test_q_sample_matches_diffusers_add_noise():
    diffusers = pytest.importorskip("diffusers")
    ref = diffusers.DDPMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2")
    g = torch.Generator().manual_seed(1)
    x0, noise = torch.randn(5, 8, 3, generator=g), torch.randn(5, 8, 3, generator=g)
    t = torch.randint(0, 100, (5,), generator=g)
    torch.testing.assert_close(q_sample(x0, t, noise, NoiseSchedule().alphas_cumprod),
                               ref.add_noise(x0, noise, t), atol=1e-5, rtol=1e-5)


def test_forward_process_statistics():
    # x_t has mean sqrt(abar) x0 and variance 1 - abar: a chunk dissolves into N(0, I) at t = T-1.
    sched = NoiseSchedule()
    x0 = torch.full((20000, 1), 0.7)
    noise = torch.randn(20000, 1, generator=torch.Generator().manual_seed(2))
    for ti in (5, 60, 99):
        a = float(sched.alphas_cumprod[ti])
        x_t = q_sample(x0, torch.full((20000,), ti), noise, sched.alphas_cumprod)
        assert x_t.mean().item() == pytest.approx(math.sqrt(a) * 0.7, abs=0.03)
        assert x_t.var().item() == pytest.approx(1 - a, abs=0.03)


def test_epsilon_loss_closed_form_and_gradient():
    sched = NoiseSchedule()
    g = torch.Generator().manual_seed(3)
    x0, noise = torch.randn(6, 16, 2, generator=g), torch.randn(6, 16, 2, generator=g)
    t = torch.randint(0, 100, (6,), generator=g)
    w = torch.tensor(0.5, requires_grad=True)
    cond = torch.randn(6, 1, 1, generator=g)

    def eps_model(x_t, tt, c):
        return w * x_t + c

    loss = epsilon_loss(eps_model, x0, cond, t, noise, sched.alphas_cumprod)
    a = sched.alphas_cumprod[t][:, None, None]
    x_t = a.sqrt() * x0 + (1 - a).sqrt() * noise
    expected = ((0.5 * x_t + cond - noise) ** 2).mean()
    torch.testing.assert_close(loss, expected)
    loss.backward()
    torch.testing.assert_close(w.grad, (2 * (0.5 * x_t + cond - noise) * x_t).mean())
    # A perfect predictor has zero loss.
    assert epsilon_loss(lambda x, tt, c: noise, x0, None, t, noise, sched.alphas_cumprod).item() == 0.0


def test_diffusion_loss_draws_t_and_noise_from_generator():
    sched = NoiseSchedule()
    x0 = torch.randn(8, 16, 2, generator=torch.Generator().manual_seed(4))
    seen = {}

    def loss_fn(eps_model, x0_, cond, t, noise, abar):
        seen["t"], seen["noise"] = t, noise
        return epsilon_loss(eps_model, x0_, cond, t, noise, abar)

    model = lambda x, t, c: torch.zeros_like(x)  # noqa: E731
    l1 = diffusion_loss(model, x0, None, sched, generator=torch.Generator().manual_seed(9), loss_fn=loss_fn)
    g = torch.Generator().manual_seed(9)
    t_ref = torch.randint(0, 100, (8,), generator=g)
    noise_ref = torch.randn(8, 16, 2, generator=g)
    assert torch.equal(seen["t"], t_ref) and torch.equal(seen["noise"], noise_ref)
    torch.testing.assert_close(l1, (noise_ref ** 2).mean())


def test_diffusion_loss_rejects_nan():
    with pytest.raises(ValueError, match="NaN"):
        diffusion_loss(lambda x, t, c: x, torch.full((2, 4, 2), float("nan")), None, NoiseSchedule())
