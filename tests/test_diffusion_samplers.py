"""DDPM / DDIM samplers agree step for step with diffusers' schedulers (the reference implementation)."""

from __future__ import annotations

import pytest
import torch

from coursekit.diffusion import DDIMSampler, DDPMSampler, NoiseSchedule, ddim_step

diffusers = pytest.importorskip("diffusers")

SHAPE = (3, 16, 2)  # (B, Tp, Da)


def _eps_model():
    """A fixed, t-dependent, x-dependent fake noise predictor (so every step differs)."""
    w = torch.randn(2, 2, generator=torch.Generator().manual_seed(7))

    def eps_model(x, t, cond):
        return torch.tanh(x @ w) * 0.8 + 0.3 * torch.sin(t.float()[:, None, None] / 7.0 + x)

    return eps_model


def _reference(kind: str, T: int, n: int, spacing: str = "leading"):
    kw = dict(num_train_timesteps=T, beta_schedule="squaredcos_cap_v2", clip_sample=True,
              prediction_type="epsilon", timestep_spacing=spacing)
    if kind == "ddpm":
        sched = diffusers.DDPMScheduler(variance_type="fixed_small", **kw)
    else:
        sched = diffusers.DDIMScheduler(set_alpha_to_one=True, steps_offset=0, **kw)
    sched.set_timesteps(n)
    return sched


def _compare(ours, ref, eta=None, seed=0, scale=1.0):
    eps_model = _eps_model()
    assert ours.timesteps.tolist() == ref.timesteps.tolist()
    x_ours = torch.randn(SHAPE, generator=torch.Generator().manual_seed(seed)) * scale
    x_ref = x_ours.clone()
    g_ours, g_ref = torch.Generator().manual_seed(seed + 1), torch.Generator().manual_seed(seed + 1)
    for t in ref.timesteps.tolist():
        tb = torch.full((SHAPE[0],), t, dtype=torch.long)
        eps_ref = eps_model(x_ref, tb, None)
        kw = {} if eta is None else {"eta": eta}
        x_ref = ref.step(eps_ref, t, x_ref, generator=g_ref, **kw).prev_sample
        x_ours = ours.step(eps_model(x_ours, tb, None), t, x_ours, generator=g_ours)
        torch.testing.assert_close(x_ours, x_ref, atol=1e-5, rtol=1e-5, msg=f"diverged at t={t}")
    assert torch.isfinite(x_ours).all()


@pytest.mark.parametrize("n", [100, 10])
def test_ddpm_matches_diffusers_step_for_step(n):
    schedule = NoiseSchedule(num_train_timesteps=100)
    _compare(DDPMSampler(schedule, num_inference_steps=n), _reference("ddpm", 100, n))


@pytest.mark.parametrize("n,eta", [(10, 0.0), (100, 0.0), (16, 0.0), (10, 0.5), (100, 1.0), (8, 1.0)])
def test_ddim_matches_diffusers_step_for_step(n, eta):
    schedule = NoiseSchedule(num_train_timesteps=100)
    _compare(DDIMSampler(schedule, num_inference_steps=n, eta=eta), _reference("ddim", 100, n), eta=eta)


@pytest.mark.parametrize("n,eta", [(10, 0.0), (16, 0.0), (8, 0.5), (100, 0.0), (7, 0.0)])
def test_ddim_trailing_spacing_matches_diffusers_step_for_step(n, eta):
    schedule = NoiseSchedule(num_train_timesteps=100)
    ours = DDIMSampler(schedule, num_inference_steps=n, eta=eta, timestep_spacing="trailing")
    assert ours.timesteps[0] == 99  # starts at the last trained timestep
    _compare(ours, _reference("ddim", 100, n, "trailing"), eta=eta)


def test_clipping_is_exercised_and_still_matches():
    # Large samples drive x0_hat far outside [-1, 1], so clip_sample matters.
    schedule = NoiseSchedule(num_train_timesteps=100)
    _compare(DDIMSampler(schedule, 10), _reference("ddim", 100, 10), eta=0.0, scale=5.0)
    _compare(DDPMSampler(schedule), _reference("ddpm", 100, 100), scale=5.0)


def test_sample_loop_matches_manual_steps_and_is_seeded():
    schedule = NoiseSchedule()
    eps_model = _eps_model()
    sampler = DDIMSampler(schedule, num_inference_steps=10, eta=0.5)
    x0, traj = sampler.sample(eps_model, SHAPE, generator=torch.Generator().manual_seed(3),
                              return_trajectory=True)
    assert traj.shape == (11, *SHAPE)
    torch.testing.assert_close(traj[-1], x0)
    again = sampler.sample(eps_model, SHAPE, generator=torch.Generator().manual_seed(3))
    torch.testing.assert_close(again, x0)
    # The same loop through diffusers, starting from the same x_T and generator stream.
    ref = _reference("ddim", 100, 10)
    g = torch.Generator().manual_seed(3)
    x = torch.randn(SHAPE, generator=g)
    torch.testing.assert_close(x, traj[0])
    for t in ref.timesteps.tolist():
        x = ref.step(eps_model(x, torch.full((SHAPE[0],), t), None), t, x, eta=0.5, generator=g).prev_sample
    torch.testing.assert_close(x0, x, atol=1e-5, rtol=1e-5)


def test_ddim_step_fn_argument_is_used():
    calls = []

    def spy(*args, **kwargs):
        calls.append(kwargs["eta"])
        return ddim_step(*args, **kwargs)

    sampler = DDIMSampler(NoiseSchedule(), num_inference_steps=4, step_fn=spy)
    sampler.sample(_eps_model(), SHAPE, generator=torch.Generator().manual_seed(0))
    assert calls == [0.0] * 4


def test_bad_arguments_raise():
    s = NoiseSchedule()
    with pytest.raises(ValueError, match="num_inference_steps"):
        DDIMSampler(s, num_inference_steps=0)
    with pytest.raises(ValueError, match="num_inference_steps"):
        DDPMSampler(s, num_inference_steps=101)
    with pytest.raises(ValueError, match="eta"):
        DDIMSampler(s, eta=-0.1)
    with pytest.raises(ValueError, match="'middle'"):
        DDIMSampler(s, timestep_spacing="middle")
    with pytest.raises(ValueError, match="x_T"):
        DDIMSampler(s).sample(_eps_model(), SHAPE, x_T=torch.zeros(1, 16, 2))


@pytest.mark.parametrize("make", [lambda s: DDIMSampler(s, 5), lambda s: DDIMSampler(s, 5, eta=1.0),
                                  lambda s: DDPMSampler(s, 20)])
def test_samples_from_a_unet_are_clipped_to_the_action_range(make):
    from coursekit.nn import ConditionalUnet1D, UNet1DConfig

    torch.manual_seed(0)
    net = ConditionalUnet1D(2, 3, UNet1DConfig(down_dims=(8, 16), diffusion_step_embed_dim=8)).eval()
    x0 = make(NoiseSchedule()).sample(net, (2, 8, 2), cond=torch.randn(2, 3),
                                      generator=torch.Generator().manual_seed(1))
    assert x0.shape == (2, 8, 2) and torch.isfinite(x0).all()
    # The last step lands on abar = 1, where x_prev is the clipped x0 estimate itself.
    assert x0.abs().max() <= 1.0 + 1e-6
