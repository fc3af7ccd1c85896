"""ACTPolicy: shapes, loss masking, z = 0 determinism, normalisation, checkpoints, a tiny training run."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from coursekit.data import EpisodeDataset  # noqa: E402
from coursekit.data.batches import ChunkBatcher  # noqa: E402
from coursekit.data.features import env_obs_features, training_arrays  # noqa: E402
from coursekit.execution.ensembling import TemporalEnsemble  # noqa: E402
from coursekit.execution.receding import RecedingHorizon  # noqa: E402
from coursekit.nn.vision import VisionEncoderConfig  # noqa: E402
from coursekit.policies.act import ACTConfig, ACTPolicy  # noqa: E402

Do, Da, K = 5, 3, 6


def tiny_config(**kw) -> ACTConfig:
    base = dict(obs_dim=Do, action_dim=Da, chunk_size=K, hidden_dim=16, ff_dim=32, n_heads=4, n_encoder_layers=1,
                n_decoder_layers=2, n_vae_encoder_layers=1, latent_dim=4, dropout=0.0)
    return ACTConfig(**{**base, **kw})


def tiny_policy(seed: int = 0, **kw) -> ACTPolicy:
    torch.manual_seed(seed)
    policy = ACTPolicy(tiny_config(**kw))
    rng = np.random.default_rng(seed)
    policy.fit_normalizers({"obs": rng.normal(2.0, 3.0, size=(200, Do))}, rng.normal(-1.0, 0.5, size=(200, Da)))
    return policy


def batch(B: int = 4, seed: int = 0, n_pad: int = 2) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    pad = torch.zeros(B, K, dtype=torch.bool)
    pad[:, K - n_pad:] = True
    return {"obs": torch.randn(B, 1, Do, generator=g), "action": torch.randn(B, K, Da, generator=g), "action_is_pad": pad}


def test_loss_keys_and_predict_shapes():
    policy = tiny_policy()
    out = policy.compute_loss(batch())
    assert set(out) == {"loss", "l1", "kl"} and all(v.shape == () for v in out.values())
    torch.testing.assert_close(out["loss"], out["l1"] + 10.0 * out["kl"])
    assert policy.predict_chunk(torch.zeros(3, 1, Do)).shape == (3, K, Da)
    chunk = policy.predict_chunk(np.zeros((2, Do)))  # (B, Do) works too; numpy in, numpy out
    assert isinstance(chunk, np.ndarray) and chunk.shape == (2, K, Da)


def test_l1_is_mean_over_non_padded_steps():
    """With use_vae=False (z = 0) the L1 term is checkable by hand against decode()."""
    policy = tiny_policy(use_vae=False)
    b = batch(n_pad=3)
    out = policy.compute_loss(b)
    obs_n = policy.normalizers["obs"].normalize(b["obs"][:, 0])
    pred = policy.decode(obs_n, torch.zeros(4, 4))
    target = policy.normalizers["action"].normalize(b["action"])
    valid = ~b["action_is_pad"]
    torch.testing.assert_close(out["l1"], (pred - target).abs()[valid].mean())
    assert out["kl"].item() == 0.0


def test_padded_steps_do_not_change_the_loss():
    policy = tiny_policy()
    b = batch(n_pad=2)
    changed = dict(b, action=b["action"].clone())
    changed["action"][:, -2:] += 100.0  # padded: ignored by the L1 AND masked in the CVAE encoder
    gen = lambda: torch.Generator().manual_seed(7)  # noqa: E731 - same reparameterisation noise
    a, c = policy.compute_loss(b, generator=gen()), policy.compute_loss(changed, generator=gen())
    torch.testing.assert_close(a["loss"], c["loss"])
    changed["action"][:, 0] += 1.0  # a real step: the loss must move
    assert not torch.allclose(a["loss"], policy.compute_loss(changed, generator=gen())["loss"])


def test_prediction_uses_z_zero_and_is_deterministic_even_in_train_mode():
    policy = tiny_policy(dropout=0.3).train()
    obs = torch.randn(2, 1, Do)
    first, second = policy.predict_chunk(obs), policy.predict_chunk(obs)
    torch.testing.assert_close(first, second)
    assert policy.training, "predict_chunk must restore the training flag"
    policy.eval()
    want = policy.normalizers["action"].unnormalize(policy.decode(policy.normalizers["obs"].normalize(obs[:, 0]),
                                                                  torch.zeros(2, 4)))
    torch.testing.assert_close(first, want)


def test_normalisation_is_mean_std_with_clipped_std():
    policy = ACTPolicy(tiny_config())
    obs = np.zeros((10, Do))
    obs[:, 0] = np.arange(10)  # dimension 0 varies, the others are constant
    policy.fit_normalizers({"obs": obs}, np.ones((10, Da)))
    norm = policy.normalizers["obs"]
    np.testing.assert_allclose(norm.mean, obs.mean(0), atol=1e-6)
    np.testing.assert_allclose(norm.std, [obs[:, 0].std(), 0.01, 0.01, 0.01, 0.01], rtol=1e-6)


def test_kl_fn_is_pluggable_and_gradients_reach_every_part():
    policy = tiny_policy()
    calls = []

    def kl_fn(mu, logvar):
        calls.append(mu.shape)
        return (mu ** 2).sum(1).mean()

    out = policy.compute_loss(batch(), kl_fn=kl_fn)
    assert calls == [(4, 4)]
    out["loss"].backward()
    for name in ("vae_encoder.layers.0.ff.net.0.weight", "vae_latent_proj.weight", "latent_proj.weight",
                 "transformer.query_embed.weight", "action_head.weight"):
        grad = dict(policy.named_parameters())[name].grad
        assert grad is not None and grad.abs().sum() > 0, name


def test_checkpoint_round_trip(tmp_path):
    from coursekit.checkpoint import load_checkpoint, save_checkpoint

    policy = tiny_policy(seed=3)
    save_checkpoint(policy, tmp_path / "ckpt", training={"steps": 0})
    loaded = load_checkpoint(tmp_path / "ckpt", device="cpu", expected_type="act")
    assert isinstance(loaded, ACTPolicy) and loaded.config == policy.config
    obs = np.random.default_rng(0).normal(size=(2, 1, Do))
    np.testing.assert_allclose(loaded.predict_chunk(obs), policy.predict_chunk(obs), atol=1e-6)


def test_config_validation_and_paper_preset():
    with pytest.raises(ValueError, match="hidden_dim"):
        ACTConfig(hidden_dim=30, n_heads=4)
    with pytest.raises(ValueError, match="n_action_steps"):
        ACTConfig(chunk_size=10, n_action_steps=11)
    with pytest.raises(ValueError, match="kl_weight"):
        ACTConfig(kl_weight=-1.0)
    paper = ACTConfig.paper()
    assert (paper.hidden_dim, paper.ff_dim, paper.n_heads, paper.n_encoder_layers, paper.n_decoder_layers,
            paper.chunk_size, paper.latent_dim, paper.kl_weight) == (512, 3200, 8, 4, 7, 100, 32, 10.0)


def test_default_executors():
    policy = tiny_policy()
    assert isinstance(policy.make_executor(), TemporalEnsemble)
    assert policy.make_executor().ensemble_decay == 0.01
    open_loop = tiny_policy(temporal_ensembling=False).make_executor()
    assert isinstance(open_loop, RecedingHorizon) and open_loop.n_action_steps == K
    ex = policy.make_executor()
    ex.reset(np.zeros((2, Do)))
    assert ex.act(np.zeros((2, Do))).shape == (2, Da)


def test_image_tokens_smoke():
    vision = VisionEncoderConfig(image_size=(32, 32), crop_size=(32, 32), widths=(16, 16, 16, 16), group_size=8)
    policy = tiny_policy(obs_type="image", vision=vision)
    b = dict(batch(), image=torch.randint(0, 256, (4, 1, 3, 32, 32), dtype=torch.uint8))
    out = policy.compute_loss(b)
    assert torch.isfinite(out["loss"])
    chunk = policy.predict_chunk({"obs": np.zeros((2, 1, Do)), "image": np.zeros((2, 1, 3, 32, 32), dtype=np.uint8)})
    assert chunk.shape == (2, K, Da)
    with pytest.raises(ValueError, match="image"):
        policy.predict_chunk(np.zeros((2, 1, Do)))
    with pytest.raises(ValueError, match=r"float observation 'image' must lie in \[0, 1\]; got values in \[0, 255\]"):
        policy.predict_chunk({"obs": np.zeros((2, 1, Do)), "image": np.full((2, 1, 3, 32, 32), 255.0, np.float32)
                              * (np.arange(2)[:, None, None, None, None] > 0)})  # 0..255 floats: white, refused


@pytest.mark.slow
def test_batcher_pads_and_training_reduces_the_loss():
    rng = np.random.default_rng(0)
    eps = [{"qpos": rng.normal(size=(L, 14)), "env_state": rng.normal(size=(L, 7)),
            "action": np.cumsum(rng.normal(size=(L, 14)), axis=0)} for L in (9, 12)]
    ds = EpisodeDataset.from_episodes(eps)
    obs, action = training_arrays(ds, "aloha_state")
    assert obs["obs"].shape == (21, 21)
    batcher = ChunkBatcher(obs, action, ds.episode_ends, chunk_size=K, batch_size=8, seed=0)
    b = batcher.batch(torch.tensor([8, 9]))  # last step of episode 0, first of episode 1
    assert b["action_is_pad"][0].tolist() == [False] + [True] * (K - 1)
    assert not b["action_is_pad"][1].any()
    assert float(b["action"][0, 1:].abs().sum()) == 0.0
    torch.testing.assert_close(b["action"][1], torch.as_tensor(action[9:9 + K]))
    torch.testing.assert_close(b["obs"][1], torch.as_tensor(obs["obs"][9]))
    np.testing.assert_allclose(env_obs_features("aloha_state", [{"qpos": np.ones(14), "env_state": np.zeros(7)}]),
                               np.r_[np.ones(14), np.zeros(7)][None])

    torch.manual_seed(0)
    policy = ACTPolicy(tiny_config(obs_dim=21, action_dim=14, kl_weight=1.0))
    policy.fit_normalizers(obs, action)
    opt = torch.optim.AdamW(policy.parameters(), lr=3e-3)
    fixed = batcher.batch(torch.arange(8))
    first = policy.compute_loss(fixed)["l1"].item()
    for _ in range(60):
        loss = policy.compute_loss(fixed)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert policy.compute_loss(fixed)["l1"].item() < 0.5 * first
