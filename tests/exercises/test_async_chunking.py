"""Exercise 11.1 (async_chunking): naive asynchronous chunk execution under an inference delay of d steps.

Reference: the closed form of the schedule, written as plain loops. Request k happens at step
r_k = k * P with P = max(Ta, d) and is computed from the observations up to r_k; it arrives at
a_0 = 0 (the episode's first chunk is ready at once) and a_k = r_k + d for k >= 1. At step t the
robot executes the newest ARRIVED chunk k at index start + min(t - r_k, L - 1) (L = Tp - start:
past its end a chunk holds its last action).
"""

from __future__ import annotations

import numpy as np
import pytest

EXERCISE = "async_chunking"


class Recorder:
    """Chunk predictor: chunk[b, j] = (100 * call + j, b); remembers every history it was given."""

    def __init__(self, horizon: int = 8):
        self.horizon, self.calls = horizon, []

    def __call__(self, obs_history):
        self.calls.append(np.array(obs_history, copy=True))
        b = obs_history.shape[0]
        chunk = np.zeros((b, self.horizon, 2))
        chunk[:, :, 0] = 100 * (len(self.calls) - 1) + np.arange(self.horizon)
        chunk[:, :, 1] = np.arange(b)[:, None]
        return chunk


def schedule(t: int, ta: int, d: int, start: int, horizon: int) -> tuple[int, int]:
    """(chunk k, index into the chunk) executed at step t, by the closed form above."""
    period, length = max(ta, d), horizon - start
    k_now = 0
    for k in range(t + 1):
        r = k * period
        arrival = 0 if k == 0 else r + d
        if arrival <= t:
            k_now = k
    return k_now, start + min(t - k_now * period, length - 1)


def run(student, to: int, ta: int, d: int, steps: int = 24, batch: int = 2, horizon: int = 8):
    pred = Recorder(horizon)
    ex = student.AsyncChunking(pred, n_obs_steps=to, n_action_steps=ta, delay=d)
    obs = [np.full((batch, 3), float(t)) for t in range(steps)]  # the observation at step t is all t
    ex.reset(obs[0])
    actions = np.stack([np.asarray(ex.act(obs[t])) for t in range(steps)])  # (steps, B, 2)
    return actions, pred, ex


def check(actions, to, ta, d, horizon=8):
    for t in range(len(actions)):
        k, i = schedule(t, ta, d, to - 1, horizon)
        assert actions[t, 0, 0] == 100 * k + i, (
            f"step {t} (Ta={ta}, d={d}): expected chunk {k} index {i} (= {100 * k + i}), got {actions[t, 0, 0]}")


def test_zero_delay_is_receding_horizon(student):
    actions, pred, _ = run(student, to=1, ta=4, d=0)
    check(actions, 1, 4, 0)
    assert len(pred.calls) == 6, f"with d = 0 a chunk is requested every Ta = 4 steps: 6 in 24 steps, got {len(pred.calls)}"


@pytest.mark.parametrize("ta,d", [(4, 2), (4, 1), (3, 3)])
def test_switch_indices_on_a_hand_built_stream(student, ta, d):
    actions, _, ex = run(student, to=1, ta=ta, d=d)
    check(actions, 1, ta, d)
    assert ex.switches[:3] == [0, ta + d, 2 * ta + d], f"switches at 0, Ta + d, 2 Ta + d; got {ex.switches[:3]}"


def test_requests_see_the_newest_observations(student):
    _, pred, ex = run(student, to=2, ta=4, d=2)
    assert ex.requests[:4] == [0, 4, 8, 12], f"requests every max(Ta, d) = 4 steps, got {ex.requests[:4]}"
    for k, h in enumerate(pred.calls[:4]):
        r = 4 * k
        np.testing.assert_array_equal(h[0, :, 0], [max(r - 1, 0), r], err_msg=f"request {k} at step {r} sees steps r-1, r")


def test_delay_longer_than_ta_holds_the_last_action(student):
    actions, pred, ex = run(student, to=1, ta=2, d=5, horizon=6)
    check(actions, 1, 2, 5, horizon=6)
    assert ex.requests[:3] == [0, 5, 10], "with d > Ta request when the last one arrives: every d steps"


def test_batch_rows_and_start_offset(student):
    actions, _, _ = run(student, to=3, ta=3, d=2, batch=3, horizon=10)
    check(actions, 3, 3, 2, horizon=10)
    np.testing.assert_array_equal(actions[:, :, 1], np.tile(np.arange(3.0), (len(actions), 1)),
                                  err_msg="row b of the chunk is environment b's: index the chunk as chunk[:, i]")
