"""Exercise 2.1 (noise_loss): forward noising q_sample and the epsilon-prediction loss.

References: the closed form x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) eps written here, diffusers'
DDPMScheduler.add_noise, and torch's F.mse_loss. The epsilon_loss tests pass the REFERENCE
q_sample (``reference_q_sample``) as ``q_sample_fn``, so a wrong q_sample fails only its own tests.
"""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from coursekit.diffusion.schedules import NoiseSchedule

EXERCISE = "noise_loss"

ABAR = NoiseSchedule(num_train_timesteps=100).alphas_cumprod  # (T,), read-only in the tests


def reference_q_sample(x0, t, noise, alphas_cumprod):
    """The closed form, written here: what epsilon_loss's tests use instead of the student's q_sample."""
    a = alphas_cumprod[t].reshape(-1, *([1] * (x0.ndim - 1)))  # (B, 1, ..., 1)
    return a.sqrt() * x0 + (1 - a).sqrt() * noise


def _inputs(seed, shape=(4, 16, 2)):
    g = torch.Generator().manual_seed(seed)
    x0 = torch.rand(shape, generator=g) * 2 - 1
    noise = torch.randn(shape, generator=g)
    t = torch.randint(0, 100, (shape[0],), generator=g)
    return x0, noise, t


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_q_sample_matches_closed_form(student, seed):
    x0, noise, t = _inputs(seed)
    got = student.q_sample(x0, t, noise, ABAR.clone())
    assert got.shape == x0.shape, f"shape {tuple(got.shape)}, expected {tuple(x0.shape)}"
    for i, ti in enumerate(t.tolist()):
        a = float(ABAR[ti])
        want = math.sqrt(a) * x0[i] + math.sqrt(1 - a) * noise[i]
        torch.testing.assert_close(got[i], want, rtol=1e-5, atol=1e-6,
                                   msg=lambda m: f"sample {i} (t={ti}) differs from sqrt(abar_t) x0 + sqrt(1-abar_t) eps: {m}")


def test_q_sample_endpoints_and_other_shapes(student):
    x0, noise, _ = _inputs(3, shape=(3, 5))  # any trailing shape, e.g. (B, D)
    for ti in (0, 99):  # nearly clean at t = 0, nearly pure noise at t = T-1
        t = torch.full((3,), ti, dtype=torch.long)
        got = student.q_sample(x0, t, noise, ABAR.clone())
        assert got.shape == (3, 5), f"shape {tuple(got.shape)}, expected (3, 5)"
        a = float(ABAR[ti])
        torch.testing.assert_close(got, math.sqrt(a) * x0 + math.sqrt(1 - a) * noise, rtol=1e-5, atol=1e-6,
                                   msg=lambda m: f"(B, D) inputs at t={ti}: {m}")
    assert torch.isfinite(got).all()


def test_q_sample_matches_diffusers_add_noise(student):
    diffusers = pytest.importorskip("diffusers")
    ref = diffusers.DDPMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2")
    x0, noise, t = _inputs(4, shape=(6, 8, 3))
    got = student.q_sample(x0, t, noise, ABAR.clone())
    torch.testing.assert_close(got, ref.add_noise(x0, noise, t), rtol=1e-5, atol=1e-5)


def test_epsilon_loss_is_mse_on_noise(student):
    x0, noise, t = _inputs(5)
    cond = torch.randn(4, 1, 1, generator=torch.Generator().manual_seed(6))
    seen = {}

    def eps_model(x_t, tt, c):  # stays in the test's process: the worker calls back
        seen["x_t"], seen["t"], seen["cond"] = x_t, tt, c
        return 0.5 * x_t + c

    loss = student.epsilon_loss(eps_model, x0, cond, t, noise, ABAR.clone(), q_sample_fn=reference_q_sample)
    x_t = reference_q_sample(x0, t, noise, ABAR)
    assert "x_t" in seen, "epsilon_loss never called eps_model(x_t, t, cond)"
    torch.testing.assert_close(seen["x_t"], x_t, rtol=1e-5, atol=1e-6,
                               msg=lambda m: f"the x_t given to eps_model must be q_sample_fn(x0, t, noise, abar): {m}")
    assert torch.equal(seen["t"], t), "the t given to eps_model differs from the t passed in: pass it unchanged"
    assert seen["cond"] is not None and torch.equal(seen["cond"], cond), \
        "the cond given to eps_model differs from the cond passed in: pass it unchanged"
    assert torch.is_tensor(loss), f"the loss must be a tensor, got {type(loss).__name__}"
    assert loss.ndim == 0, f"the loss must be a scalar (0-d tensor), got shape {tuple(loss.shape)}"
    torch.testing.assert_close(loss, F.mse_loss(0.5 * x_t + cond, noise), rtol=1e-5, atol=1e-7,
                               msg=lambda m: f"the loss value differs from mean((eps_model(x_t) - noise)^2): {m}")


def test_epsilon_loss_uses_q_sample_fn_and_backpropagates(student, sandbox):
    x0, noise, t = _inputs(7)
    fake_x_t = torch.full_like(x0, 2.0)
    model = sandbox.new("coursekit.grading.worker:scale_model", 0.3)  # eps = w * x_t, w a parameter (in the worker)
    loss, (grads,) = sandbox.grad(student.epsilon_loss, model, x0, None, t, noise, ABAR.clone(),
                                  q_sample_fn=lambda *args: fake_x_t, wrt=(model,))
    torch.testing.assert_close(loss.detach(), ((0.6 - noise) ** 2).mean(), rtol=1e-5, atol=1e-7,
                               msg=lambda m: f"the loss value: build x_t with the q_sample_fn argument: {m}")
    assert grads["w"] is not None, "no gradient reached the model's parameter: keep the loss a torch expression"
    torch.testing.assert_close(grads["w"], (2 * (0.6 - noise) * 2.0).mean(), rtol=1e-4, atol=1e-6,
                               msg=lambda m: f"d loss / d w (the model's parameter) differs: {m}")
