"""Chunk windows against the papers' definitions, written out by hand."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coursekit.data import ActionChunks, SequenceWindows


def _reference_dp_windows(lengths, horizon, n_obs, n_act):
    """Diffusion Policy's sequence sampler, spelled out one window at a time."""
    windows, start = [], 0
    for n in lengths:
        for s in range(-(n_obs - 1), n - horizon + (n_act - 1) + 1):
            windows.append([start + min(max(s + j, 0), n - 1) for j in range(horizon)])
        start += n
    return np.array(windows)


def test_small_example_by_hand():
    w = SequenceWindows.build(np.array([5, 9]), horizon=6, n_obs_steps=2, n_action_steps=3)
    expected = [[0, 0, 1, 2, 3, 4], [0, 1, 2, 3, 4, 4], [1, 2, 3, 4, 4, 4],
                [5, 5, 6, 7, 8, 8], [5, 6, 7, 8, 8, 8]]
    np.testing.assert_array_equal(w.indices, expected)
    np.testing.assert_array_equal(w.episode, [0, 0, 0, 1, 1])


@settings(max_examples=60, deadline=None)
@given(lengths=st.lists(st.integers(16, 40), min_size=1, max_size=4),
       n_obs=st.integers(1, 3), n_act=st.integers(1, 8))
def test_matches_reference_sampler(lengths, n_obs, n_act):
    horizon = 16
    ends = np.cumsum(lengths)
    w = SequenceWindows.build(ends, horizon=horizon, n_obs_steps=n_obs, n_action_steps=n_act)
    np.testing.assert_array_equal(w.indices, _reference_dp_windows(lengths, horizon, n_obs, n_act))
    # every window stays inside one episode
    starts = np.concatenate([[0], ends[:-1]])
    assert np.all(w.indices >= starts[w.episode][:, None]) and np.all(w.indices < ends[w.episode][:, None])


def test_gather_shapes_and_values():
    obs = np.arange(20, dtype=float).reshape(10, 2)
    act = -np.arange(10, dtype=float)[:, None]
    w = SequenceWindows.build(np.array([10]), horizon=4, n_obs_steps=2, n_action_steps=2)
    o, a = w.gather(obs, act, np.array([0, 3]))
    assert o.shape == (2, 2, 2) and a.shape == (2, 4, 1)
    np.testing.assert_array_equal(o[0], obs[[0, 0]])  # padded before with the first step
    np.testing.assert_array_equal(a[1, :, 0], -np.array([2, 3, 4, 5]))


def test_bad_config_names_the_value():
    with pytest.raises(ValueError, match="n_action_steps=10"):
        SequenceWindows.build(np.array([30]), horizon=8, n_obs_steps=2, n_action_steps=10)
    with pytest.raises(ValueError, match="horizon"):
        SequenceWindows.build(np.array([30]), horizon=0)
    with pytest.raises(ValueError, match="increasing"):
        SequenceWindows.build(np.array([5, 3]))


def test_act_chunks_pad_past_the_end():
    c = ActionChunks.build(np.array([3, 5]), chunk_size=3)
    np.testing.assert_array_equal(c.start, np.arange(5))
    np.testing.assert_array_equal(c.is_pad, [[0, 0, 0], [0, 0, 1], [0, 1, 1], [0, 0, 1], [0, 1, 1]])
    act = np.arange(1, 6, dtype=float)[:, None]
    o, a, pad = c.gather(act * 10, act, np.array([1, 3]))
    np.testing.assert_array_equal(o[:, 0], [20, 40])
    np.testing.assert_array_equal(a[:, :, 0], [[2, 3, 0], [4, 5, 0]])  # zero where padded
    np.testing.assert_array_equal(pad, [[0, 0, 1], [0, 0, 1]])
