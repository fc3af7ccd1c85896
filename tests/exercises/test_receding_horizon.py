"""Exercise 5.1 (receding_horizon): execute Ta actions of each chunk from index To - 1, then re-plan.

References: the closed form of which chunk and which index every executed action comes from
(chunk k is made at step k * Ta; step t executes chunk t // Ta, index To - 1 + t % Ta), and of
which observations each re-plan sees (the newest To, the first one repeated at an episode start).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coursekit.grading.compare import assert_close

EXERCISE = "receding_horizon"


class Recorder:
    """Chunk predictor: chunk[b, j] = (100 * call + j, b); remembers every history it was given."""

    def __init__(self, horizon: int = 16):
        self.horizon, self.calls = horizon, []

    def __call__(self, obs_history):
        self.calls.append(np.array(obs_history, copy=True))
        b = obs_history.shape[0]
        chunk = np.zeros((b, self.horizon, 2))
        chunk[:, :, 0] = 100 * (len(self.calls) - 1) + np.arange(self.horizon)
        chunk[:, :, 1] = np.arange(b)[:, None]
        return chunk


def run(student, to: int, ta: int, steps: int = 20, batch: int = 3):
    pred = Recorder()
    ex = student.RecedingHorizon(pred, n_obs_steps=to, n_action_steps=ta)
    obs = [np.full((batch, 4), float(t)) for t in range(steps)]  # observation at step t is all t
    ex.reset(obs[0])
    actions = np.stack([np.asarray(ex.act(obs[t])) for t in range(steps)])  # (steps, B, 2)
    return actions, pred


def expected_actions(to: int, ta: int, steps: int) -> np.ndarray:
    t = np.arange(steps)
    return 100 * (t // ta) + (to - 1) + t % ta  # (steps,) chunk t // Ta, index To - 1 + t % Ta


def test_first_chunk_executes_pred_to_minus_1_onwards(student):
    actions, pred = run(student, to=2, ta=8, steps=8)
    assert actions.shape == (8, 3, 2), f"actions stacked over 8 steps have shape {actions.shape}, expected (8, B=3, Da=2)"
    np.testing.assert_array_equal(actions[:, 0, 0], np.arange(1, 9),
                                  err_msg="with To = 2, Ta = 8 the first 8 actions are chunk[:, 1:9]")
    np.testing.assert_array_equal(actions[:, :, 1], np.tile(np.arange(3), (8, 1)),
                                  err_msg="environment b must get row b of the chunk")
    assert len(pred.calls) == 1, f"{len(pred.calls)} predictor calls for 8 steps with Ta = 8, expected 1"


@pytest.mark.parametrize("to, ta", [(2, 8), (1, 4), (3, 5), (2, 1), (4, 13)])
def test_replans_every_ta_steps(student, to, ta):
    actions, pred = run(student, to, ta, steps=20)
    np.testing.assert_array_equal(actions[:, 0, 0], expected_actions(to, ta, 20),
                                  err_msg=f"To={to}, Ta={ta}: step t must execute chunk t // Ta at index To-1 + t % Ta")
    assert len(pred.calls) == int(np.ceil(20 / ta)), f"{len(pred.calls)} predictor calls, expected ceil(20 / Ta)"


@pytest.mark.parametrize("to, ta", [(2, 8), (3, 4)])
def test_history_holds_newest_to_observations(student, to, ta):
    _, pred = run(student, to, ta, steps=20)
    for k, hist in enumerate(pred.calls):
        assert hist.shape == (3, to, 4), f"history shape {hist.shape}, expected (B, To, Do) = (3, {to}, 4)"
        s = k * ta
        want = [max(0, s - to + 1 + i) for i in range(to)]  # oldest first; before step 0: copies of step 0
        np.testing.assert_array_equal(hist[0, :, 0], want, err_msg=f"re-plan at step {s}: history of steps {want}")


def test_reset_repeats_first_observation_and_forgets_plan(student):
    pred = Recorder()
    ex = student.RecedingHorizon(pred, n_obs_steps=2, n_action_steps=8)
    ex.reset(np.zeros((1, 3)))
    for t in range(3):
        ex.act(np.full((1, 3), float(t)))
    ex.reset(np.full((1, 3), 7.0))
    a = np.asarray(ex.act(np.full((1, 3), 7.0)))
    assert len(pred.calls) == 2, "after reset the first act must re-plan (the old plan is forgotten)"
    np.testing.assert_array_equal(pred.calls[1][0, :, 0], [7.0, 7.0], err_msg="reset fills the history with copies of obs")
    assert a[0, 0] == 101, f"first action after reset is chunk[:, To-1] = 101, got {a[0, 0]}"


def test_works_with_torch_tensors(student):
    def predict(h):
        return h[:, -1:, :2].repeat(1, 16, 1) + torch.arange(16.0)[None, :, None]  # (B, 16, 2)

    ex = student.RecedingHorizon(predict, n_obs_steps=2, n_action_steps=8)
    obs = torch.tensor([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    ex.reset(obs)
    a = ex.act(obs)
    assert torch.is_tensor(a) and a.shape == (2, 2), f"expected a (B, Da) = (2, 2) tensor, got {type(a).__name__} {tuple(a.shape)}"
    assert_close(a, torch.tensor([[2.0, 3.0], [5.0, 6.0]]))
