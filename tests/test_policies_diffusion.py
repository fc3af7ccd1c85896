"""DiffusionPolicy: shapes, the loss against its closed form, normalisation, sampling, bad input, images."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from coursekit.data import EpisodeDataset, MinMaxNormalizer
from coursekit.data.features import pusht_state_features
from coursekit.diffusion.loss import q_sample
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.nn.vision import VisionEncoderConfig
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
from coursekit.policies.factory import make_policy

TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


def synthetic_pusht(n_episodes: int = 6, length: int = 30, seed: int = 0) -> EpisodeDataset:
    """Random-walk PushT-like demonstrations: state (N, 5) with an unwrapped angle, action (N, 2)."""
    rng = np.random.default_rng(seed)
    episodes = []
    for _ in range(n_episodes):
        state = 250 + np.cumsum(rng.normal(0, 5, size=(length, 5)), axis=0)
        state[:, 4] = np.cumsum(rng.normal(0, 0.3, size=length))  # angle, unwrapped
        episodes.append({"state": state, "action": state[:, :2] + rng.normal(0, 3, size=(length, 2))})
    return EpisodeDataset.from_episodes(episodes, {"seed": 0, "n_episodes": n_episodes})


def tiny_policy(**kwargs) -> DiffusionPolicy:
    torch.manual_seed(0)
    policy = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, **kwargs))
    policy.set_normalizers({"obs": MinMaxNormalizer(np.zeros(6), np.full(6, 500.0)),
                            "action": MinMaxNormalizer(np.full(2, 100.0), np.full(2, 400.0))})
    return policy


def test_compute_loss_matches_closed_form():
    policy = tiny_policy()
    obs = torch.rand(5, 2, 6) * 500
    action = 100 + torch.rand(5, 16, 2) * 300
    out = policy.compute_loss({"obs": obs, "action": action}, generator=torch.Generator().manual_seed(3))
    assert set(out) >= {"loss"} and out["loss"].ndim == 0
    # Redraw t and eps exactly as diffusion_loss does, and evaluate the defining equation.
    gen = torch.Generator().manual_seed(3)
    t = torch.randint(0, 100, (5,), generator=gen)
    eps = torch.randn((5, 16, 2), generator=gen)
    a0 = (action - 250.0) / 150.0  # min-max to [-1, 1] by hand
    cond = ((obs - 250.0) / 250.0).reshape(5, 12)
    abar = policy.schedule.alphas_cumprod[t][:, None, None]
    a_t = abar.sqrt() * a0 + (1 - abar).sqrt() * eps
    assert torch.allclose(a_t, q_sample(a0, t, eps, policy.schedule.alphas_cumprod), atol=1e-6)
    expected = F.mse_loss(policy.unet(a_t, t, cond), eps)
    assert torch.allclose(out["loss"], expected, atol=1e-6)
    out["loss"].backward()
    assert all(p.grad is not None for p in policy.unet.parameters())


def test_predict_chunk_shapes_types_and_range():
    policy = tiny_policy()
    obs = np.random.default_rng(0).uniform(0, 500, size=(3, 2, 6)).astype(np.float32)
    chunk = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(0))
    assert isinstance(chunk, np.ndarray) and chunk.shape == (3, 16, 2)
    # clip_sample keeps the normalised chunk in [-1, 1], i.e. inside the data's [min, max]
    assert chunk.min() >= 100.0 - 1e-3 and chunk.max() <= 400.0 + 1e-3
    single = policy.predict_chunk(torch.as_tensor(obs[0]), generator=torch.Generator().manual_seed(0))
    assert torch.is_tensor(single) and single.shape == (16, 2)
    ddpm = policy.predict_chunk(obs, sampler="ddpm", num_inference_steps=5)
    assert ddpm.shape == (3, 16, 2)


def test_predict_chunk_deterministic_given_generator():
    policy = tiny_policy()
    obs = torch.rand(2, 2, 6) * 500
    a = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(7))
    b = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(7))
    c = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(8))
    assert torch.equal(a, b) and not torch.equal(a, c)
    chunk, traj = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(7), return_trajectory=True)
    assert torch.equal(chunk, a) and traj.shape == (11, 2, 16, 2)


def test_make_sampler_defaults():
    policy = tiny_policy()
    assert len(policy.make_sampler().timesteps) == 10
    assert len(policy.make_sampler("ddpm").timesteps) == 100
    assert len(policy.make_sampler("ddim", 4).timesteps) == 4
    with pytest.raises(ValueError, match="sampler"):
        policy.make_sampler("euler")


@pytest.mark.parametrize("bad", [np.zeros((3, 2, 5)), np.zeros((3, 3, 6)), np.zeros((3, 6)), np.zeros((2, 2, 2, 6))])
def test_wrong_observation_shape_is_a_clear_error(bad):
    with pytest.raises(ValueError, match="shape"):
        tiny_policy().predict_chunk(bad)


def test_nan_in_batch_or_observation_is_a_clear_error():
    policy = tiny_policy()
    obs, action = torch.rand(4, 2, 6), torch.rand(4, 16, 2)
    obs[1, 0, 3] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        policy.compute_loss({"obs": obs, "action": action})
    with pytest.raises(ValueError, match="NaN"):
        policy.predict_chunk(obs)
    with pytest.raises(ValueError, match="action"):
        policy.compute_loss({"obs": torch.rand(4, 2, 6), "action": torch.rand(4, 8, 2)})


def test_missing_normalizers_are_reported():
    policy = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY))
    with pytest.raises(ValueError, match="normaliser"):
        policy.predict_chunk(np.zeros((1, 2, 6)))
    with pytest.raises(ValueError, match="dimensions"):
        policy.set_normalizers({"obs": MinMaxNormalizer(np.zeros(5), np.ones(5)),
                                "action": MinMaxNormalizer(np.zeros(2), np.ones(2))})


@pytest.mark.parametrize("kwargs, match", [
    ({"sampler": "euler"}, "sampler"), ({"n_action_steps": 16}, "fit in Tp"), ({"horizon": 15}, "divisible"),
    ({"obs_type": "depth"}, "obs_type"), ({"num_inference_steps": 0}, "num_inference_steps"),
    ({"beta_schedule": "sigmoid"}, "beta_schedule")])
def test_config_validation_shows_bad_value(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DiffusionPolicyConfig(unet=TINY, **kwargs)


def test_factory_fits_normalizers_and_features_to_the_data():
    ds = synthetic_pusht()
    policy, batches, _ = make_policy("diffusion", ds, batch_size=8, unet=TINY)
    feats = pusht_state_features(ds["state"])
    assert policy.config.obs_dim == 6 and policy.config.action_dim == 2
    np.testing.assert_allclose(policy.normalizers["obs"].low, feats.min(0))
    np.testing.assert_allclose(policy.normalizers["action"].high, ds["action"].max(0), rtol=1e-6)
    batch = next(iter(batches))
    assert batch["obs"].shape == (8, 2, 6) and batch["action"].shape == (8, 16, 2)
    assert torch.isfinite(policy.compute_loss(batch)["loss"])


def test_image_observation_smoke():
    """Image DP: uint8 frames through the GroupNorm ResNet + spatial softmax, loss and sampling."""
    vision = VisionEncoderConfig(image_size=(32, 32), crop_size=(28, 28), widths=(16, 16, 16, 16),
                                 blocks_per_stage=1, num_keypoints=8, feature_dim=16)
    torch.manual_seed(0)
    policy = DiffusionPolicy(DiffusionPolicyConfig(obs_type="image", features="pusht_image", obs_dim=2,
                                                   unet=TINY, vision=vision))
    policy.set_normalizers({"agent_pos": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0)),
                            "action": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0))})
    batch = {"image": torch.randint(0, 256, (3, 2, 3, 32, 32), dtype=torch.uint8),
             "agent_pos": torch.rand(3, 2, 2) * 512, "action": torch.rand(3, 16, 2) * 512}
    loss = policy.compute_loss(batch)["loss"]
    loss.backward()
    assert torch.isfinite(loss) and policy.vision_encoder is not None
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in policy.vision_encoder.parameters())
    chunk = policy.predict_chunk({"image": batch["image"].numpy(), "agent_pos": batch["agent_pos"].numpy()},
                                 num_inference_steps=2)
    assert chunk.shape == (3, 16, 2)
    with pytest.raises(ValueError, match="image"):
        policy.predict_chunk(np.zeros((3, 2, 2)))
    with pytest.raises(ValueError, match="image"):
        policy.predict_chunk({"image": np.zeros((3, 2, 3, 96, 96), np.uint8), "agent_pos": np.zeros((3, 2, 2))})


def test_image_policy_end_to_end_smoke():
    """Rendered PushT frames -> a few training steps -> a 2-episode evaluation from pixel observations."""
    from coursekit.evaluate import evaluate_pusht
    from coursekit.train import TrainConfig, train

    vision = VisionEncoderConfig(image_size=(32, 32), crop_size=(28, 28), widths=(16, 16, 16, 16),
                                 blocks_per_stage=1, num_keypoints=8, feature_dim=16)
    ds = synthetic_pusht(n_episodes=2, length=20)
    policy, batches, _ = make_policy("diffusion", ds, features="pusht_image", batch_size=4, unet=TINY,
                                        vision=vision, num_inference_steps=2)
    batch = next(iter(batches))
    assert batch["image"].shape == (4, 2, 3, 32, 32) and batch["image"].dtype == torch.uint8
    assert batch["agent_pos"].shape == (4, 2, 2)
    result = train(policy, batches, TrainConfig(max_steps=2, warmup_steps=1, progress=False))
    r = evaluate_pusht(result.policy, n_episodes=2, max_steps=3, progress=False)
    assert r.chunk_calls == 1 and 0.0 <= r.score <= 1.0


def test_evaluation_overrides_are_validated_copies():
    policy = tiny_policy()
    copy = policy.with_config(ddim_timestep_spacing="trailing", n_action_steps=4)
    assert copy.config.ddim_timestep_spacing == "trailing" and copy.execution_spec().n_action_steps == 4
    assert policy.config.ddim_timestep_spacing == "leading" and policy.config.n_action_steps == 8  # untouched
    assert copy.unet is policy.unet  # the same weights, not a second model
    with pytest.raises(ValueError, match="To - 1 \\+ Ta must fit in Tp"):
        policy.with_config(n_action_steps=16)  # validated by the config's __post_init__
    with pytest.raises(ValueError, match="not evaluation settings"):
        policy.with_config(horizon=32)  # would not fit the weights
    with pytest.raises(ValueError, match="ddim_timestep_spacing"):
        policy.with_config(ddim_timestep_spacing="middle")
    assert policy.describe_sampling(sampler="ddpm")["num_inference_steps"] == 100
    with pytest.raises(ValueError, match="no sampling option"):
        policy.check_sampling({"temperature": 0.5})
