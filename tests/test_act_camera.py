"""ACT from one camera on the arm pair ('aloha_image'): frames rendered from stored states, a few
training steps, and a closed-loop evaluation through the same adapter and executors as every policy."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("mujoco")

from coursekit.envs.aloha.env import AlohaEnv, render_physics_states  # noqa: E402
from coursekit.evaluate.closed_loop import evaluate  # noqa: E402
from coursekit.evaluate.tasks import make_adapter  # noqa: E402
from coursekit.execution.ensembling import TemporalEnsemble  # noqa: E402
from coursekit.experts.aloha_scripted import collect_transfer_cube  # noqa: E402
from coursekit.nn.vision import VisionEncoderConfig  # noqa: E402
from coursekit.policies.factory import make_policy  # noqa: E402
from coursekit.train import TrainConfig, train  # noqa: E402

SIZE = (24, 32)
TINY_VISION = VisionEncoderConfig(widths=(8, 16), blocks_per_stage=1, group_size=4, image_size=SIZE, crop_size=SIZE,
                                  random_crops=False)


@pytest.fixture(scope="module")
def demos():
    return collect_transfer_cube(1, 0, progress=False, workers=1)


def test_a_stored_state_renders_the_frame_the_env_observes(demos):
    env = AlohaEnv(task="transfer_cube", obs_type="pixels", render_size=SIZE)
    obs, _ = env.reset(seed=0)  # the demonstration of seed 0 starts here
    frames = render_physics_states("transfer_cube", demos["physics_qpos"][:1], SIZE)
    assert frames.shape == (1, 3, *SIZE) and frames.dtype == np.uint8
    np.testing.assert_array_equal(frames[0].transpose(1, 2, 0), obs["pixels"])
    with pytest.raises(ValueError, match=r"physics_qpos of 'transfer_cube' must be \(N, "):
        render_physics_states("transfer_cube", demos["physics_qpos"][:2, :5], SIZE)
    env.close()


def test_image_act_trains_on_rendered_frames_and_runs_closed_loop(demos):
    policy, batches, recipe = make_policy("act", demos, features="aloha_image", recipe="cpu", seed=0, batch_size=4,
                                          vision=TINY_VISION, chunk_size=10, hidden_dim=32, ff_dim=64, n_heads=2)
    assert (policy.config.obs_type, policy.config.obs_dim) == ("image", 14)
    batch = next(iter(batches))
    assert batch["image"].shape == (4, 3, *SIZE) and batch["image"].dtype == torch.uint8 and batch["obs"].shape == (4, 14)
    result = train(policy, batches, TrainConfig(**{**recipe, "max_steps": 2, "warmup_steps": 1, "progress": False,
                                                   "checkpoint_every_minutes": None}))
    adapter = make_adapter("transfer_cube", result.policy)
    run = evaluate(result.policy, adapter, [100000], max_steps=6, progress=False, dataset_meta=demos.meta)
    assert run.length[0] == 6 and np.isfinite(run.max_reward).all()
    frame = np.zeros((1, 3, 48, 64), dtype=np.uint8)  # a camera of another size: one line that says so
    with pytest.raises(ValueError, match="24x32"):
        adapter.obs_fn([{"qpos": np.zeros(14), "pixels": frame[0].transpose(1, 2, 0)}])


def test_rendering_needs_the_stored_physics_state(demos):
    from coursekit.data import EpisodeDataset

    bare = EpisodeDataset.from_episodes([{"qpos": demos["qpos"][:20], "action": demos["action"][:20]}],
                                        {"task": "transfer_cube"})
    with pytest.raises(ValueError, match="stores 'physics_qpos'"):
        make_policy("act", bare, features="aloha_image", vision=TINY_VISION, chunk_size=4, hidden_dim=16, ff_dim=32,
                    n_heads=2)


def test_temporal_ensembling_of_dict_observations_matches_the_array_path():
    rng = np.random.default_rng(0)
    low = rng.normal(size=(6, 2, 3))  # (T, B, Do)
    frames = rng.integers(0, 256, size=(6, 2, 3, 4, 4), dtype=np.uint8)  # (T, B, C, H, W)
    seen = []

    def from_low(history):  # (B, To, Do) -> a chunk (B, 5, 2) that depends on the whole history
        h = history["agent_pos"] if isinstance(history, dict) else history
        if isinstance(history, dict):
            seen.append(history["image"].dtype)
        return np.repeat(h.sum(axis=1)[:, None, :2], 5, axis=1) + np.arange(5)[None, :, None]

    ref, got = TemporalEnsemble(from_low, n_obs_steps=2, ensemble_decay=0.1), TemporalEnsemble(from_low, 2, 0.1)
    ref.reset(low[0])
    got.reset({"agent_pos": low[0], "image": frames[0]})
    for t in range(6):
        np.testing.assert_allclose(got.act({"agent_pos": low[t], "image": frames[t]}), ref.act(low[t]))
    assert seen == [np.uint8] * 6  # frames reach the policy as uint8, not as 0..255 floats
    with pytest.raises(ValueError, match="act expects obs of shape"):
        got.act({"agent_pos": low[0, :1], "image": frames[0, :1]})


def test_the_arm_pair_preset_gives_act_a_6_by_8_grid_of_image_tokens():
    from coursekit.policies.act import ImageTokens

    config = VisionEncoderConfig.preset("arm_pair")
    tokens, positions = ImageTokens(config, 32)(torch.zeros(2, 3, *config.image_size))
    assert config.image_size == (96, 128) and tokens.shape == (2, 6 * 8, 32) and positions.shape == (6 * 8, 32)
