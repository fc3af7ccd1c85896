"""Evaluation under delay: the glue (strategies by name, seeds, smoothness figures, latency -> d)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import coursekit
from coursekit.evaluate.delayed import STRATEGIES, check_strategy, evaluate_delayed, latency_delay, smoothness

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


def test_latency_to_delay_at_each_control_rate():
    assert latency_delay(95.0, "pusht") == 1 and latency_delay(150.0, "pusht") == 2
    assert latency_delay(95.0, "transfer_cube") == 5
    with pytest.raises(ValueError, match="task"):
        latency_delay(10.0, "cartpole")


def test_strategy_checks(dp):
    assert set(STRATEGIES) == {"sync", "async", "ensemble", "rtc"}
    with pytest.raises(ValueError, match="unknown strategy"):
        check_strategy("hopeful", dp)
    act_like = type("P", (), {"policy_type": "act"})()
    with pytest.raises(ValueError, match="diffusion or flow"):
        check_strategy("rtc", act_like)
    with pytest.raises(ValueError, match="delay"):
        evaluate_delayed(dp, "pusht", "async", -1, [100000])
    with pytest.raises(ValueError, match="sampling option"):
        evaluate_delayed(dp, "pusht", "async", 1, [100000], sampling={"temperature": 2.0})


@pytest.mark.parametrize("strategy", ["sync", "rtc"])
def test_evaluate_delayed_is_deterministic_and_labelled(dp, strategy):
    seeds = [100000, 100001]
    r1 = evaluate_delayed(dp, "pusht", strategy, 2, seeds, seed=3, max_steps=24, record=True)
    r2 = evaluate_delayed(dp, "pusht", strategy, 2, seeds, seed=3, max_steps=24, record=True)
    np.testing.assert_array_equal(r1.actions, r2.actions)
    assert r1.info["strategy"] == strategy and r1.info["delay"] == 2 and r1.info["switches"][0] == 0
    assert (r1.info["guided_calls"] > 0) == (strategy == "rtc")
