"""FlowMatchingPolicy: DP's backbone with the flow-matching loss and an ODE sampler; checkpoints and CLI."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from coursekit.data import MinMaxNormalizer
from coursekit.flow.loss import sample_flow_time
from coursekit.flow.sampler import euler_step
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies import get_policy_class
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
from coursekit.policies.flow import FlowMatchingPolicy, FlowMatchingPolicyConfig

TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)
NORMS = {"obs": MinMaxNormalizer(np.zeros(6), np.full(6, 500.0)),
         "action": MinMaxNormalizer(np.zeros(2), np.full(2, 500.0))}

pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


def tiny(**kwargs) -> FlowMatchingPolicy:
    torch.manual_seed(0)
    return FlowMatchingPolicy(FlowMatchingPolicyConfig(unet=TINY, **kwargs), NORMS)


def test_registered_and_same_backbone_as_diffusion_policy():
    assert get_policy_class("flow") is FlowMatchingPolicy
    flow, dp = tiny(), DiffusionPolicy(DiffusionPolicyConfig(unet=TINY), NORMS)
    assert {k: tuple(v.shape) for k, v in flow.state_dict().items()} == \
        {k: tuple(v.shape) for k, v in dp.state_dict().items()}


def test_loss_is_the_flow_matching_loss_on_normalised_chunks():
    policy = tiny(time_sampling="uniform")
    obs, action = torch.rand(4, 2, 6) * 500, torch.rand(4, 16, 2) * 500
    loss = policy.compute_loss({"obs": obs, "action": action}, generator=torch.Generator().manual_seed(3))["loss"]
    g = torch.Generator().manual_seed(3)
    t = sample_flow_time(4, "uniform", generator=g)
    e = torch.randn(4, 16, 2, generator=g)
    a0 = action / 250.0 - 1.0
    x_t = t[:, None, None] * e + (1 - t[:, None, None]) * a0
    cond = (obs / 250.0 - 1.0).reshape(4, 12)
    v = policy.unet(x_t, 100.0 * t, cond)  # time_scale 100: the embedding sees 100 t
    torch.testing.assert_close(loss, F.mse_loss(v, e - a0), rtol=1e-5, atol=1e-6)


def test_predict_chunk_is_euler_from_seeded_noise_clamped_and_raw():
    policy = tiny()
    obs = np.random.default_rng(1).uniform(0, 500, (3, 2, 6)).astype(np.float32)
    a = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(5), num_inference_steps=4)
    assert a.shape == (3, 16, 2) and isinstance(a, np.ndarray)
    assert a.min() >= 0.0 and a.max() <= 500.0
    # by hand: x1 from the generator, four Euler steps of -1/4, clamp, unnormalise
    x = torch.randn(3, 16, 2, generator=torch.Generator().manual_seed(5))
    cond = torch.as_tensor(obs / 250.0 - 1.0).reshape(3, 12)
    with torch.no_grad():
        for i in range(4):
            t = torch.full((3,), 1.0 - i / 4)
            x = x - 0.25 * policy.unet(x, 100.0 * t, cond)
    np.testing.assert_allclose(a, ((x.clamp(-1, 1) + 1) * 250.0).numpy(), rtol=1e-4, atol=1e-3)
    # a student's step plugs in; the trajectory has N + 1 iterates
    c, traj = policy.predict_chunk(torch.as_tensor(obs), generator=torch.Generator().manual_seed(5),
                                   num_inference_steps=4, step_fn=euler_step, return_trajectory=True)
    np.testing.assert_allclose(c.numpy(), a, rtol=1e-5, atol=1e-4)
    assert traj.shape == (5, 3, 16, 2)
    m = policy.predict_chunk(obs[0], generator=torch.Generator().manual_seed(5), sampler="midpoint",
                             num_inference_steps=2)
    assert m.shape == (16, 2)
    assert policy.describe_sampling(sampler="midpoint", num_inference_steps=2)["network_calls"] == 4


def test_bad_arguments_name_the_value():
    with pytest.raises(ValueError, match="'gamma'"):
        FlowMatchingPolicyConfig(time_sampling="gamma")
    with pytest.raises(ValueError, match="'rk4'"):
        FlowMatchingPolicyConfig(integration_method="rk4")
    for bad in (0, 1001, True, 99999999999999999999):  # unbounded N would integrate forever
        with pytest.raises(ValueError, match=rf"num_inference_steps must be an int in \[1, 1000\] for a flow policy, got {bad}"):
            FlowMatchingPolicyConfig(num_inference_steps=bad)
    policy = tiny()
    obs = np.zeros((1, 2, 6), dtype=np.float32)
    with pytest.raises(ValueError, match="'ddim'"):
        policy.predict_chunk(obs, sampler="ddim")
    for bad in (0, 1001, 10**20):  # an explicit 0 is refused, never replaced by the config's 10
        with pytest.raises(ValueError, match=f"got {bad}"):
            policy.predict_chunk(obs, num_inference_steps=bad)
        with pytest.raises(ValueError, match=f"got {bad}"):
            policy.describe_sampling(num_inference_steps=bad)
    with pytest.raises(TypeError, match="'steps'"):  # one name for N: num_inference_steps
        policy.predict_chunk(obs, steps=2)
    with pytest.raises(ValueError, match="'steps'"):
        policy.describe_sampling(steps=2)


@pytest.mark.slow
def test_learns_two_modes_that_regression_would_average():
    """Two equally likely chunks (+0.5, -0.5) for one observation: flow samples both, 1 step gives the mean."""
    policy = tiny(time_sampling="uniform")
    opt = torch.optim.Adam(policy.parameters(), lr=3e-3)
    obs = torch.full((64, 2, 6), 250.0)
    g = torch.Generator().manual_seed(0)
    for _ in range(250):
        sign = torch.where(torch.rand(64, generator=g) < 0.5, 1.0, -1.0)
        action = 250.0 + 125.0 * sign[:, None, None].expand(64, 16, 2)  # normalised +-0.5
        loss = policy.compute_loss({"obs": obs, "action": action}, generator=g)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    many = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(1), num_inference_steps=10) / 250.0 - 1.0
    means = many.mean(dim=(1, 2))  # (64,) per-sample mean of the normalised chunk
    assert (means > 0.3).float().mean() > 0.25 and (means < -0.3).float().mean() > 0.25, means
    one = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(1), num_inference_steps=1) / 250.0 - 1.0
    # one Euler step heads for the mean between the modes (exactly, for a perfectly learned field)
    assert float(one.mean(dim=(1, 2)).abs().mean()) < 0.5 * float(means.abs().mean())


def test_checkpoint_round_trip_and_cli(tmp_path):
    from coursekit.checkpoint import load_checkpoint, save_checkpoint

    policy = tiny(num_inference_steps=3)
    save_checkpoint(policy, tmp_path / "ck")
    back = load_checkpoint(tmp_path / "ck")
    assert isinstance(back, FlowMatchingPolicy) and back.config == policy.config
    obs = np.random.default_rng(2).uniform(0, 500, (2, 2, 6)).astype(np.float32)
    np.testing.assert_array_equal(policy.predict_chunk(obs, generator=torch.Generator().manual_seed(0)),
                                  back.predict_chunk(obs, generator=torch.Generator().manual_seed(0)))
