"""Evaluation: protocol bookkeeping against a hand-run loop, batching, determinism, executor plug-in."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coursekit.data import MinMaxNormalizer
from coursekit.data.features import pusht_state_features
from coursekit.envs.pusht import PushTEnv
from coursekit.evaluate import EVAL_SEED_START, check_seeds_disjoint, evaluate_pusht, heldout_seeds, rollout
from coursekit.execution.receding import RecedingHorizon
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig

TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


def tiny_policy() -> DiffusionPolicy:
    torch.manual_seed(0)
    return DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, num_inference_steps=2),
                           {"obs": MinMaxNormalizer(np.array([0, 0, 0, 0, -1, -1.0]), np.array([512, 512, 512, 512, 1, 1.0])),
                            "action": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0))})


def toward_block(obs_history: np.ndarray) -> np.ndarray:
    """Hand-built chunk predictor: every action of the chunk targets the block's newest position."""
    target = obs_history[:, -1, 2:4]  # (B, 2)
    return np.repeat(target[:, None, :], 16, axis=1)  # (B, 16, 2)


def test_rollout_matches_a_hand_run_loop():
    seeds, steps = [3, 11], 25
    result = rollout(toward_block, lambda: PushTEnv(max_episode_steps=steps),
                     lambda obs: pusht_state_features(np.stack(obs)), seeds,
                     lambda pc: RecedingHorizon(pc, 2, 8), max_steps=steps, progress=False, record=True)
    for i, seed in enumerate(seeds):  # the same policy, one env at a time, by hand
        env = PushTEnv(max_episode_steps=steps)
        obs, _ = env.reset(seed=seed)
        best, ok = 0.0, False
        for t in range(steps):
            if t % 8 == 0:  # re-plan every Ta = 8 steps from the newest observation
                target = obs[2:4].copy()
            obs, reward, terminated, truncated, info = env.step(target)
            best, ok = max(best, reward), ok or info["is_success"]
            if terminated or truncated:
                break
        assert result.max_reward[i] == pytest.approx(best) and result.success[i] == ok
        np.testing.assert_allclose(result.states[i, -1], env.get_state(), atol=1e-3)  # features are float32
    assert result.chunk_calls == int(np.ceil(steps / 8))  # one batched call per re-plan for both envs
    assert result.states.shape == (2, steps + 1, 7) and result.actions.shape == (2, steps, 2)
    assert result.score == pytest.approx(result.max_reward.mean())


def test_evaluation_is_deterministic_by_seed():
    policy = tiny_policy()
    a = evaluate_pusht(policy, n_episodes=2, max_steps=12, progress=False, record=True)
    b = evaluate_pusht(policy, n_episodes=2, max_steps=12, progress=False, record=True)
    c = evaluate_pusht(policy, n_episodes=2, max_steps=12, progress=False, record=True, seed=1)
    np.testing.assert_array_equal(a.actions, b.actions)
    assert not np.array_equal(a.actions, c.actions)  # other sampling noise, other actions
    assert a.seeds == [EVAL_SEED_START, EVAL_SEED_START + 1]
    s = a.summary()
    assert s["sampler"] == "ddim" and s["num_inference_steps"] == 2 and s["episodes"] == 2
    assert evaluate_pusht(policy, n_episodes=1, max_steps=2, sampler="ddpm", progress=False).info["num_inference_steps"] == 100


def test_executor_class_is_plugged_in_explicitly():
    built = []

    class Counting(RecedingHorizon):
        def __init__(self, predict_chunk, n_obs_steps, n_action_steps):
            super().__init__(predict_chunk, n_obs_steps, n_action_steps=4)  # a different Ta, visibly
            built.append(self)

    result = evaluate_pusht(tiny_policy(), n_episodes=2, max_steps=9, executor_cls=Counting, progress=False)
    assert len(built) == 1 and result.chunk_calls == 3  # ceil(9 / 4) batched calls


def test_heldout_seeds_are_disjoint_from_demonstrations():
    assert heldout_seeds(3) == [100000, 100001, 100002]
    check_seeds_disjoint(heldout_seeds(50), {"seed": 0, "n_episodes": 200})
    with pytest.raises(ValueError, match="demonstrations"):  # a skipped seed moves the later ones on
        check_seeds_disjoint([201], {"seed": 0, "n_episodes": 200, "episode_seeds": [*range(150), *range(151, 202)]})
    with pytest.raises(ValueError, match="demonstrations"):
        check_seeds_disjoint([5, 6], {"seed": 0, "n_episodes": 200})
    with pytest.raises(ValueError, match="demonstrations"):
        evaluate_pusht(tiny_policy(), seeds=[1], dataset_meta={"seed": 0, "n_episodes": 2}, progress=False)
    with pytest.raises(ValueError, match="n_episodes"):
        heldout_seeds(0)
