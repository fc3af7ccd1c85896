"""ACT plumbing end to end: make_policy + train recipe, and evaluate_aloha on a few steps of the arm pair."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("mujoco")

from coursekit.data import EpisodeDataset  # noqa: E402
from coursekit.data.features import default_features  # noqa: E402
from coursekit.evaluate.aloha import evaluate_aloha  # noqa: E402
from coursekit.execution.receding import RecedingHorizon  # noqa: E402
from coursekit.policies.factory import make_policy  # noqa: E402
from coursekit.tasks.aloha import STATE_COLUMNS  # noqa: E402
from coursekit.train import TrainConfig  # noqa: E402


def _tiny_aloha_policy():
    rng = np.random.default_rng(0)
    eps = [{"qpos": rng.normal(size=(30, 14)), "env_state": rng.normal(size=(30, 7)),
            "action": rng.normal(size=(30, 14)) * 0.1} for _ in range(2)]
    ds = EpisodeDataset.from_episodes(eps, {"seed": 0, "n_episodes": 2})
    assert default_features(ds.arrays) == "aloha_state"
    policy, batches, recipe = make_policy("act", ds, chunk_size=8, hidden_dim=16, ff_dim=32, n_heads=2, batch_size=4)
    assert recipe["batch_size"] == 4 and recipe["lr"] == 1e-5  # the paper recipe, batch size overridden
    return policy, batches, ds


def test_factory_and_recipes():
    policy, batches, ds = _tiny_aloha_policy()
    assert (policy.config.obs_dim, policy.config.action_dim, policy.config.features) == (21, 14, "aloha_state")
    assert set(policy.normalizers) == {"obs", "action"} and len(batches) == ds.n_steps
    paper = TrainConfig.recipe("paper", "act", max_steps=1)
    assert (paper.lr, paper.weight_decay, paper.batch_size, paper.lr_schedule, paper.ema) == (1e-5, 1e-4, 8, "constant", False)
    cpu = TrainConfig.recipe("cpu", "act", max_steps=1)
    assert (cpu.lr, cpu.batch_size, cpu.lr_schedule, cpu.warmup_steps) == (3e-4, 16, "cosine", 200)
    with pytest.raises(ValueError, match="unknown training recipe 'gpu'"):
        TrainConfig.recipe("gpu", "act", max_steps=1)


def test_evaluate_aloha_reports_stages_and_records_states():
    policy, _, ds = _tiny_aloha_policy()
    r = evaluate_aloha(policy, "transfer_cube", n_episodes=2, max_steps=4, progress=False, dataset_meta=ds.meta)
    assert set(r.info["stage_rates"]) == {1, 2, 3, 4} and 0.0 <= r.info["strict_success_rate"] <= 1.0
    assert r.info["executor"] == "TemporalEnsemble" and r.chunk_calls == 4  # ensembling queries every step
    assert r.states.shape[:2] == (2, 5) and r.states.shape[2] > len(STATE_COLUMNS)
    assert r.actions.shape == (2, 4, 14)
    open_loop = evaluate_aloha(policy, n_episodes=1, max_steps=4, progress=False,
                               executor_factory=lambda pc: RecedingHorizon(pc, 1, 8))
    assert open_loop.chunk_calls == 1
    with pytest.raises(ValueError, match="seeds"):
        evaluate_aloha(policy, seeds=[1], max_steps=2, progress=False, dataset_meta=ds.meta)
