"""Delay-aware executors: hand-built chunk streams, d = 0 equals today's executors on real PushT, determinism."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import coursekit
from coursekit.data.features import get_features
from coursekit.envs.pusht import PushTEnv
from coursekit.evaluate import rollout
from coursekit.execution.delay import AsyncChunking, DelayedEnsemble, Synchronous, delay_steps
from coursekit.execution.ensembling import TemporalEnsemble
from coursekit.execution.receding import RecedingHorizon
from coursekit.execution.rtc import RealTimeChunking

pytestmark = pytest.mark.usefixtures("one_torch_thread")
CKPT = Path(coursekit.__file__).parent / "checkpoints"


class Stream:
    """Chunk k holds 100 k + j at index j (every env, every action dim): an action names its source."""

    def __init__(self, Tp: int = 6, Da: int = 1):
        self.Tp, self.Da, self.histories = Tp, Da, []

    def __call__(self, history):
        k = len(self.histories)
        self.histories.append(np.array(history, copy=True))
        c = 100.0 * k + np.arange(self.Tp)
        return np.broadcast_to(c[None, :, None], (history.shape[0], self.Tp, self.Da)).copy()


def run(executor, T: int, B: int = 2, Do: int = 3) -> list[float]:
    executor.reset(np.zeros((B, Do)))
    return [float(executor.act(np.full((B, Do), float(t + 1)))[0, 0]) for t in range(T)]


def test_delay_steps_is_ceil_of_latency_over_period():
    assert delay_steps(0.0, 10) == 0 and delay_steps(0.001, 10) == 1 and delay_steps(0.1, 10) == 1
    assert delay_steps(0.3, 10) == 3 and delay_steps(0.31, 10) == 4 and delay_steps(0.031, 50) == 2
    with pytest.raises(ValueError, match="latency_s"):
        delay_steps(-0.1, 10)
    with pytest.raises(ValueError, match="control_hz"):
        delay_steps(0.1, 0)


def test_async_switch_indices_on_a_hand_built_stream():
    # To = 1 (start 0), Ta = 4, d = 2: requests at 0, 4, 8, 12; chunk k (k >= 1) arrives at 4k + 2 and
    # starts at its index 2 (indices 0, 1 are for steps already executed from chunk k - 1).
    ex = AsyncChunking(Stream(), n_obs_steps=1, n_action_steps=4, delay=2)
    acts = run(ex, 14)
    assert acts == [0, 1, 2, 3, 4, 5, 102, 103, 104, 105, 202, 203, 204, 205]
    assert ex.requests == [0, 4, 8, 12] and ex.switches == [0, 6, 10]
    assert ex.trace[6] == (1, 2)


def test_async_with_delay_above_ta_requests_when_the_last_arrives_and_holds_past_the_end():
    stream = Stream(Tp=5)
    ex = AsyncChunking(stream, n_obs_steps=1, n_action_steps=2, delay=3)  # period max(2, 3) = 3
    acts = run(ex, 9, B=1)
    # chunk 0 (0..4) runs 0..5 (holds its last action at step 5); chunk 1 (req 3) from 6 at index 3
    assert ex.requests == [0, 3, 6] and ex.switches == [0, 6]
    assert acts == [0, 1, 2, 3, 4, 4, 103, 104, 104]
    np.testing.assert_array_equal(stream.histories[1][0, 0], np.full(3, 4.0))  # request at step 3 sees obs 3 (+1)


def test_synchronous_holds_d_steps_then_plays_the_chunk_from_its_start():
    ex = Synchronous(Stream(), n_obs_steps=1, n_action_steps=4, delay=2)
    assert run(ex, 14) == [0, 1, 2, 3, 3, 3, 100, 101, 102, 103, 103, 103, 200, 201]
    assert ex.requests == [0, 4, 10] and ex.switches == [0, 6, 12]


def test_delayed_ensemble_averages_only_arrived_chunks():
    ex = DelayedEnsemble(Stream(Tp=6), n_obs_steps=1, delay=2, ensemble_decay=0.0)
    acts = run(ex, 8)
    # requests every 2 steps; at step 4 chunks 0 (req 0) and 1 (req 2, arrived 4) cover it: (4 + 102) / 2
    assert ex.requests == [0, 2, 4, 6] and acts[:4] == [0, 1, 2, 3] and acts[4] == pytest.approx(53.0)
    assert acts[6] == pytest.approx((104 + 202) / 2)  # chunk 0 (covers 0..5) expired; chunk 3 not arrived


@pytest.mark.parametrize("To,Ta", [(1, 4), (2, 8), (2, 3)])
def test_zero_delay_is_receding_horizon_on_a_random_stream(To, Ta):
    chunks = np.random.default_rng(To * 10 + Ta).normal(size=(40, 2, 16, 2))
    for cls in (Synchronous, AsyncChunking):
        calls = {"ref": 0, "new": 0}

        def pc(key):
            def f(h):
                calls[key] += 1
                return chunks[calls[key] - 1]
            return f
        ref, new = RecedingHorizon(pc("ref"), To, Ta), cls(pc("new"), To, Ta, delay=0)
        obs = np.random.default_rng(1).normal(size=(30, 2, 3))
        ref.reset(obs[0]), new.reset(obs[0])
        for t in range(30):
            np.testing.assert_array_equal(new.act(obs[t]), ref.act(obs[t]), err_msg=f"{cls.__name__} step {t}")


def test_from_spec_builds_each_strategy():
    spec = type("Spec", (), {"n_obs_steps": 2, "n_action_steps": 8, "horizon": 16, "ensemble_decay": 0.1})()
    assert AsyncChunking.from_spec(lambda h: h, spec, delay=3).delay == 3
    assert DelayedEnsemble.from_spec(lambda h: h, spec).ensemble_decay == 0.1
    with pytest.raises(ValueError, match="predict_inpainted"):
        RealTimeChunking.from_spec(lambda h: h, spec, delay=1)
    with pytest.raises(ValueError, match="delay"):
        AsyncChunking(lambda h: h, 2, 8, delay=-1)


# ---- real PushT rollouts with the shipped checkpoints ------------------------------------------
def _pusht(policy, executor_factory, seeds=(100000, 100001), steps=40, seed=0):
    from coursekit.checkpoint import load_checkpoint  # noqa: F401  (policy loaded by the caller)

    features = get_features(policy.config.features)
    gen = torch.Generator().manual_seed(seed)

    def pc(h):
        return policy.predict_chunk(h, generator=gen) if policy.policy_type == "diffusion" else policy.predict_chunk(h)

    res = rollout(pc, lambda: PushTEnv(max_episode_steps=steps), lambda obs: features(np.stack(obs)), list(seeds),
                  executor_factory, max_steps=steps, progress=False, record=True)
    return res.actions, res.states


@pytest.fixture(scope="module")
def dp():
    from coursekit.checkpoint import load_checkpoint

    return load_checkpoint(CKPT / "pusht_diffusion_state", device="cpu")


@pytest.fixture(scope="module")
def act_pusht():
    from coursekit.checkpoint import load_checkpoint

    return load_checkpoint(CKPT / "act_pusht", device="cpu")


@pytest.mark.slow
def test_zero_delay_reproduces_receding_horizon_on_pusht(dp):
    c = dp.config
    ref, _ = _pusht(dp, lambda pc: RecedingHorizon(pc, c.n_obs_steps, c.n_action_steps))
    for name, factory in {
        "sync": lambda pc: Synchronous(pc, c.n_obs_steps, c.n_action_steps, delay=0),
        "async": lambda pc: AsyncChunking(pc, c.n_obs_steps, c.n_action_steps, delay=0),
        "rtc": lambda pc: RealTimeChunking(pc, c.n_obs_steps, c.n_action_steps, delay=0,
                                           predict_inpainted=lambda *a, **k: pytest.fail("no guidance at d = 0")),
    }.items():
        acts, _ = _pusht(dp, factory)
        np.testing.assert_array_equal(acts, ref, err_msg=f"{name} with d = 0 must be RecedingHorizon step for step")


def test_zero_delay_ensemble_reproduces_temporal_ensembling_on_pusht(act_pusht):
    m = act_pusht.config.ensemble_decay
    ref, _ = _pusht(act_pusht, lambda pc: TemporalEnsemble(pc, 1, m), steps=30)
    acts, _ = _pusht(act_pusht, lambda pc: DelayedEnsemble(pc, 1, 1, delay=0, ensemble_decay=m), steps=30)
    np.testing.assert_array_equal(acts, ref)


@pytest.mark.slow
def test_delay_loop_is_deterministic_by_seed(dp):
    c = dp.config

    def factory(pc):
        return AsyncChunking(pc, c.n_obs_steps, c.n_action_steps, delay=3)
    a1, s1 = _pusht(dp, factory, seed=7)
    a2, s2 = _pusht(dp, factory, seed=7)
    a3, _ = _pusht(dp, factory, seed=8)
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(s1, s2)
    assert not np.array_equal(a1, a3), "another sampling seed must give other actions (the loop uses the seed)"
