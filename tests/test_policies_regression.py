"""RegressionPolicy: same backbone as DiffusionPolicy, MSE on the chunk, and the conditional mean it learns."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from coursekit.data import MinMaxNormalizer
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
from coursekit.policies.regression import RegressionPolicy, RegressionPolicyConfig

TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


NORMS = {"obs": MinMaxNormalizer(np.zeros(6), np.full(6, 500.0)),
         "action": MinMaxNormalizer(np.zeros(2), np.full(2, 500.0))}


def tiny(**kwargs) -> RegressionPolicy:
    torch.manual_seed(0)
    return RegressionPolicy(RegressionPolicyConfig(unet=TINY, **kwargs), NORMS)


def test_same_backbone_as_diffusion_policy():
    reg = tiny()
    dp = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY), NORMS)
    shapes = {k: tuple(v.shape) for k, v in reg.state_dict().items()}
    assert shapes == {k: tuple(v.shape) for k, v in dp.state_dict().items()}
    assert reg.num_parameters() == dp.num_parameters()


def test_loss_is_mse_of_unet_with_zero_input_at_t0():
    policy = tiny()
    obs, action = torch.rand(4, 2, 6) * 500, torch.rand(4, 16, 2) * 500
    loss = policy.compute_loss({"obs": obs, "action": action})["loss"]
    cond = (obs / 250.0 - 1.0).reshape(4, 12)
    pred = policy.unet(torch.zeros(4, 16, 2), torch.zeros(4, dtype=torch.long), cond)
    assert torch.allclose(loss, F.mse_loss(pred, action / 250.0 - 1.0), atol=1e-6)


def test_prediction_is_deterministic_and_raw():
    policy = tiny()
    obs = np.random.default_rng(1).uniform(0, 500, (3, 2, 6)).astype(np.float32)
    a = policy.predict_chunk(obs)
    b = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(5))  # accepted, unused
    assert a.shape == (3, 16, 2) and np.array_equal(a, b)
    assert a.min() >= 0.0 and a.max() <= 500.0  # clamped to the data range
    with pytest.raises(ValueError, match="shape"):
        policy.predict_chunk(np.zeros((3, 2, 4)))
    with pytest.raises(ValueError, match="no sampling option"):  # one contract: options are checked, not ignored
        policy.check_sampling({"sampler": "ddim"})


@pytest.mark.slow
def test_learns_the_conditional_mean_of_a_bimodal_target():
    """The failure the paper predicts: two equally likely chunks (+0.5, -0.5) -> the mean 0."""
    policy = tiny()
    opt = torch.optim.Adam(policy.parameters(), lr=3e-3)
    obs = torch.full((64, 2, 6), 250.0)
    sign = torch.where(torch.arange(64) % 2 == 0, 1.0, -1.0)[:, None, None]
    action = 250.0 + 125.0 * sign.expand(64, 16, 2)  # normalised: +-0.5
    for _ in range(150):
        loss = policy.compute_loss({"obs": obs, "action": action})["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    pred = policy.predict_chunk(obs[:1])  # (1, 16, 2)
    assert torch.allclose(pred, torch.full_like(pred, 250.0), atol=15.0)  # between the modes, near neither
    assert loss.item() == pytest.approx(0.25, abs=0.02)  # the irreducible variance of the two modes
