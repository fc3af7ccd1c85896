"""Evaluation under delay: a delayed executor through evaluate(), smoothness figures, latency -> d."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import coursekit
from coursekit.evaluate import evaluate, latency_delay, make_adapter, rms_jerk, smoothness
from coursekit.execution.delay import AsyncChunking, DelayedEnsemble, Synchronous
from coursekit.execution.rtc import STRATEGIES, RealTimeChunking

pytestmark = pytest.mark.usefixtures("one_torch_thread")
CKPT = Path(coursekit.__file__).parent / "checkpoints"


@pytest.fixture(scope="module")
def dp():
    from coursekit.checkpoint import load_checkpoint

    return load_checkpoint(CKPT / "pusht_diffusion_state", device="cpu")


def test_smoothness_on_a_hand_built_trajectory():
    a = np.zeros((1, 8, 2))
    a[0, :, 0] = [0, 1, 2, 3, 10, 11, 12, 13]  # a jump of 7 at step 4
    m = smoothness(a, switches=[0, 4])
    assert m["max_step"] == pytest.approx(7.0) and m["switch_jump"] == pytest.approx(7.0)
    assert m["other_step"] == pytest.approx(1.0)
    assert m["max_jerk"] == pytest.approx(12.0)  # third differences 0, 6, -12, 6, 0 around the jump
    with pytest.raises(ValueError, match="actions"):
        smoothness(np.zeros((4, 2)))


def test_largest_and_rms_jerk_reduce_the_same_third_difference():
    a = np.random.default_rng(0).normal(size=(3, 20, 2))
    third = np.diff(a, n=3, axis=1)  # numpy's own third difference, (N, T-3, Da)
    np.testing.assert_allclose(smoothness(a)["max_jerk"], np.linalg.norm(third, axis=-1).max(axis=1).mean(), rtol=1e-12)
    np.testing.assert_allclose(rms_jerk(a), np.sqrt((third ** 2).mean(axis=(1, 2))), rtol=1e-12)


def test_latency_to_delay_at_each_control_rate():
    assert latency_delay(95.0, "pusht") == 1 and latency_delay(150.0, "pusht") == 2
    assert latency_delay(95.0, "transfer_cube") == 5
    with pytest.raises(ValueError, match="task"):
        latency_delay(10.0, "cartpole")


def test_strategies_and_bad_options(dp):
    assert STRATEGIES == {"sync": Synchronous, "async": AsyncChunking, "ensemble": DelayedEnsemble,
                          "rtc": RealTimeChunking}
    adapter = make_adapter("pusht", dp)
    with pytest.raises(ValueError, match="delay"):
        evaluate(dp, adapter, [100000], executor_cls=AsyncChunking, executor_options={"delay": -1}, progress=False)
    with pytest.raises(ValueError, match="sampling option"):
        evaluate(dp, adapter, [100000], executor_cls=AsyncChunking, executor_options={"delay": 1},
                 sampling={"temperature": 2.0}, progress=False)
    with pytest.raises(ValueError, match="prefix"):
        evaluate(dp, adapter, [100000], executor_cls=RealTimeChunking, executor_options={"delay": 1, "prefix": "paste"},
                 progress=False)


def test_rtc_needs_a_policy_with_a_guided_sampler():
    from coursekit.checkpoint import load_checkpoint

    act = load_checkpoint(CKPT / "act_pusht", device="cpu")
    regression = load_checkpoint(CKPT / "pusht_regression_state", device="cpu")
    for policy in (act, regression):
        assert not hasattr(policy, "predict_inpainted")
        with pytest.raises(ValueError, match="diffusion or flow policy"):
            evaluate(policy, make_adapter("pusht", policy), [100000], executor_cls=RealTimeChunking,
                     executor_options={"delay": 2}, progress=False)


@pytest.mark.parametrize("strategy", ["sync", "rtc"])
def test_delayed_evaluation_is_deterministic_and_labelled(dp, strategy):
    seeds, adapter = [100000, 100001], make_adapter("pusht", dp)
    runs = [evaluate(dp, adapter, seeds, seed=3, max_steps=24, record=True, executor_cls=STRATEGIES[strategy],
                     executor_options={"delay": 2}, progress=False) for _ in range(2)]
    np.testing.assert_array_equal(runs[0].actions, runs[1].actions)
    info = runs[0].info
    assert info["executor"] == STRATEGIES[strategy].__name__ and info["delay"] == 2 and info["switches"][0] == 0
    assert ("guided_calls" in info) == (strategy == "rtc")
    if strategy == "rtc":
        assert info["guided_calls"] > 0
