"""RecedingHorizon: exact executed actions and histories on a hand-built chunk predictor."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coursekit.execution.receding import RecedingHorizon, stack_history


class Recorder:
    """Chunk predictor: chunk[b, j] = (100 * call + j, b); remembers every history it saw."""

    def __init__(self, horizon: int = 16):
        self.horizon, self.calls = horizon, []

    def __call__(self, obs_history):
        self.calls.append(obs_history.copy() if isinstance(obs_history, np.ndarray) else obs_history)
        b = obs_history.shape[0]
        call = len(self.calls) - 1
        j = np.arange(self.horizon)
        chunk = np.zeros((b, self.horizon, 2))
        chunk[:, :, 0] = 100 * call + j
        chunk[:, :, 1] = np.arange(b)[:, None]
        return chunk


@pytest.mark.parametrize("to, ta", [(2, 8), (1, 4), (3, 5), (2, 1)])
def test_executes_pred_from_to_minus_1_for_ta_steps_then_replans(to, ta):
    pred = Recorder()
    ex = RecedingHorizon(pred, n_obs_steps=to, n_action_steps=ta)
    obs = [np.full((3, 4), float(t)) for t in range(20)]
    ex.reset(obs[0])
    actions = np.stack([ex.act(obs[t]) for t in range(20)])  # (20, 3, 2)
    t = np.arange(20)
    expected_first = 100 * (t // ta) + (to - 1) + t % ta  # call index, then index To-1 + offset
    np.testing.assert_array_equal(actions[:, :, 0], np.repeat(expected_first[:, None], 3, axis=1))
    np.testing.assert_array_equal(actions[:, :, 1], np.tile(np.arange(3), (20, 1)))
    assert len(pred.calls) == int(np.ceil(20 / ta)) and ex.n_calls == len(pred.calls)
    for k, hist in enumerate(pred.calls):  # history at re-plan step s = k * ta: obs s-To+1..s, clamped at 0
        s = k * ta
        want = [max(0, s - to + 1 + i) for i in range(to)]
        assert hist.shape == (3, to, 4)
        np.testing.assert_array_equal(hist[0, :, 0], want)


def test_reset_fills_history_with_first_observation_and_forgets_the_plan():
    pred = Recorder()
    ex = RecedingHorizon(pred, 2, 8)
    ex.reset(np.zeros((1, 3)))
    ex.act(np.zeros((1, 3)))
    ex.act(np.ones((1, 3)))
    ex.reset(np.full((1, 3), 5.0))
    a = ex.act(np.full((1, 3), 5.0))
    assert len(pred.calls) == 2  # re-planned at once after reset
    np.testing.assert_array_equal(pred.calls[1][0, :, 0], [5.0, 5.0])
    assert a[0, 0] == 100 + 1


def test_torch_and_dict_observations():
    seen = []

    def predict(h):
        seen.append(h)
        return torch.zeros(h["agent_pos"].shape[0], 16, 2) + h["agent_pos"][:, -1:, :1]

    ex = RecedingHorizon(predict, 2, 8)
    obs = {"image": torch.zeros(2, 3, 8, 8), "agent_pos": torch.tensor([[1.0, 2.0], [3.0, 4.0]])}
    ex.reset(obs)
    a = ex.act(obs)
    assert seen[0]["image"].shape == (2, 2, 3, 8, 8) and seen[0]["agent_pos"].shape == (2, 2, 2)
    assert torch.equal(a, torch.tensor([[1.0, 1.0], [3.0, 3.0]]))
    assert stack_history([np.zeros((2, 3)), np.ones((2, 3))]).shape == (2, 2, 3)


def test_bad_chunks_and_arguments_are_clear_errors():
    ex = RecedingHorizon(lambda h: np.zeros((h.shape[0], 8, 2)), 2, 8)  # Tp = 8 < To - 1 + Ta = 9
    ex.reset(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="shape"):
        ex.act(np.zeros((2, 3)))
    ex = RecedingHorizon(lambda h: np.zeros((1, 16, 2)), 2, 8)  # wrong batch size
    ex.reset(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="B=2"):
        ex.act(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="n_action_steps"):
        RecedingHorizon(lambda h: h, 2, 0)
    with pytest.raises(ValueError, match="callable"):
        RecedingHorizon(None, 2, 8)
