"""Exercise 2.1 (noise_loss): forward noising q_sample and the epsilon-prediction loss.

References: the closed form x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) eps written here, diffusers'
DDPMScheduler.add_noise (golden values: ``golden_values()``, stored below by tests/exercises/golden.py),
and torch's F.mse_loss. The epsilon_loss tests pass the REFERENCE
q_sample (``reference_q_sample``) as ``q_sample_fn``, so a wrong q_sample fails only its own tests.
"""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from coursekit.diffusion.schedules import NoiseSchedule
from coursekit.grading.compare import assert_close

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
        assert_close(got[i], want, rtol=1e-5, atol=1e-6,
                                   msg=lambda m: f"sample {i} (t={ti}) differs from sqrt(abar_t) x0 + sqrt(1-abar_t) eps: {m}")


def test_q_sample_endpoints_and_other_shapes(student):
    x0, noise, _ = _inputs(3, shape=(3, 5))  # any trailing shape, e.g. (B, D)
    for ti in (0, 99):  # nearly clean at t = 0, nearly pure noise at t = T-1
        t = torch.full((3,), ti, dtype=torch.long)
        got = student.q_sample(x0, t, noise, ABAR.clone())
        assert got.shape == (3, 5), f"shape {tuple(got.shape)}, expected (3, 5)"
        a = float(ABAR[ti])
        assert_close(got, math.sqrt(a) * x0 + math.sqrt(1 - a) * noise, rtol=1e-5, atol=1e-6,
                                   msg=lambda m: f"(B, D) inputs at t={ti}: {m}")
    assert torch.isfinite(got).all()


def golden_values() -> dict[str, dict[str, list]]:
    """diffusers' DDPMScheduler.add_noise on ``_inputs(4, shape=(6, 8, 3))`` (flattened). Needs
    diffusers; the test reads the stored copy (GOLDEN), written by tests/exercises/golden.py."""
    import diffusers

    ref = diffusers.DDPMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2")
    x0, noise, t = _inputs(4, shape=(6, 8, 3))
    return {"add_noise": {"t": t.tolist(), "x_t": ref.add_noise(x0, noise, t).flatten().tolist()}}


def test_q_sample_matches_diffusers_add_noise(student):
    x0, noise, t = _inputs(4, shape=(6, 8, 3))
    assert t.tolist() == GOLDEN["add_noise"]["t"]
    got = student.q_sample(x0, t, noise, ABAR.clone())
    assert_close(got, torch.tensor(GOLDEN["add_noise"]["x_t"]).reshape(6, 8, 3), rtol=1e-5, atol=1e-5)


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
    assert_close(seen["x_t"], x_t, rtol=1e-5, atol=1e-6,
                               msg=lambda m: f"the x_t given to eps_model must be q_sample_fn(x0, t, noise, abar): {m}")
    assert torch.equal(seen["t"], t), "the t given to eps_model differs from the t passed in: pass it unchanged"
    assert seen["cond"] is not None and torch.equal(seen["cond"], cond), \
        "the cond given to eps_model differs from the cond passed in: pass it unchanged"
    assert torch.is_tensor(loss), f"the loss must be a tensor, got {type(loss).__name__}"
    assert loss.ndim == 0, f"the loss must be a scalar (0-d tensor), got shape {tuple(loss.shape)}"
    assert_close(loss, F.mse_loss(0.5 * x_t + cond, noise), rtol=1e-5, atol=1e-7,
                               msg=lambda m: f"the loss value differs from mean((eps_model(x_t) - noise)^2): {m}")


def test_epsilon_loss_uses_q_sample_fn_and_backpropagates(student, sandbox):
    x0, noise, t = _inputs(7)
    fake_x_t = torch.full_like(x0, 2.0)
    model = sandbox.new("coursekit.grading.worker:scale_model", 0.3)  # eps = w * x_t, w a parameter (in the worker)
    loss, (grads,) = sandbox.grad(student.epsilon_loss, model, x0, None, t, noise, ABAR.clone(),
                                  q_sample_fn=lambda *args: fake_x_t, wrt=(model,))
    assert_close(loss.detach(), ((0.6 - noise) ** 2).mean(), rtol=1e-5, atol=1e-7,
                               msg=lambda m: f"the loss value: build x_t with the q_sample_fn argument: {m}")
    assert grads["w"] is not None, "no gradient reached the model's parameter: keep the loss a torch expression"
    assert_close(grads["w"], (2 * (0.6 - noise) * 2.0).mean(), rtol=1e-4, atol=1e-6,
                               msg=lambda m: f"d loss / d w (the model's parameter) differs: {m}")


# BEGIN GOLDEN: written by `python tests/exercises/golden.py` from golden_values(); do not edit
GOLDEN = {
    'add_noise': {
        't': [
            97, 82, 92, 14, 60, 77,
        ],
        'x_t': [
            1.55016053, -1.52995992, -0.58981812, -0.294454306, 1.18184781, 1.10672808,
            -0.711222291, -1.47909296, 0.756764829, -0.160783768, 1.04514539, 1.03681159,
            0.844952047, -0.905075729, -0.214998439, -0.311859667, -0.547851682, 0.812977433,
            0.477259606, 0.145346284, 0.310814142, -0.700599492, -1.32348394, -2.13122392,
            1.07949471, 0.0601085238, 0.0984842181, -1.2044822, -0.125022128, 0.320653379,
            1.18966186, -0.465472013, -0.720596492, -0.841773629, -0.219822407, -2.16979623,
            -0.832083464, 0.660369635, -0.0815054774, -0.0419204235, 1.27814627, 0.773133576,
            -0.317425072, 1.00543141, -1.49719083, 1.16837263, 0.381690651, -0.852876186,
            0.834593356, 0.483261317, -1.11936009, 0.618730307, -0.0905012339, -1.48011112,
            1.69489634, -0.0417492948, -2.87268972, 0.227141142, -0.680729747, -1.52395391,
            0.992099643, 0.0259658694, 0.122912742, 0.0861881077, -0.0594143197, -0.975950956,
            -1.32540607, 1.00924635, 0.787764966, 2.17696333, 1.30187511, -1.0221808,
            -0.914303899, -0.142773837, -0.445309162, 0.77832824, 0.482751548, 0.411861748,
            -0.134477675, -0.499280661, -0.0589043796, 1.02942562, 0.123877734, -0.861912489,
            -0.34716785, 0.44091323, 0.540168345, 0.644538224, -0.899171233, -1.03515255,
            0.0262520313, 0.467344254, 0.576636493, 0.876345754, 1.07993293, -0.407808244,
            -0.288817406, -0.794648051, 0.489814341, -1.57864547, 0.827461123, -0.732392073,
            0.908879757, 0.723952889, 0.0893924832, -0.695590734, 0.167829812, -0.598694086,
            0.62043184, 0.911751628, 0.498621434, 0.420778304, 0.77010864, -0.837665915,
            0.0651647672, -0.307841361, 1.47016311, 0.267014444, -0.858671069, -2.57407594,
            -0.0843128562, 0.52615869, -0.72986871, 0.0725736767, 1.64779556, -1.16089439,
            0.496704698, 1.23778749, -0.821242034, 1.52109087, 0.841275156, -0.613258719,
            -0.790224493, 1.14991558, 1.6552738, -1.84735131, 1.32191491, -1.54131484,
            0.660905361, -0.544836462, -1.23353326, 0.402524769, -0.247795433, 2.26536727,
        ],
    },
}
# END GOLDEN
