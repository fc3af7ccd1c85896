"""Exercise 1.1 (chunk_windows): Diffusion Policy training windows with edge padding.

References: a per-window brute force written straight from the definition in the docstring,
closed-form window counts, and the library's SequenceWindows on small random datasets.
"""

from __future__ import annotations

import numpy as np
import pytest

from coursekit.data.chunks import SequenceWindows

EXERCISE = "chunk_windows"


def brute_force(episode_ends, horizon, n_obs_steps, n_action_steps):
    """The definition, one window at a time: (W, Tp) indices and (W,) episode ids."""
    rows, eps, start = [], [], 0
    for e, end in enumerate(episode_ends):
        first = start - (n_obs_steps - 1)
        last = max(end - horizon + (n_action_steps - 1), first)
        for w in range(first, last + 1):
            rows.append([min(max(w + j, start), end - 1) for j in range(horizon)])
            eps.append(e)
        start = end
    return np.array(rows, dtype=np.int64).reshape(-1, horizon), np.array(eps, dtype=np.int64)


def test_shapes_and_dtypes(student):
    indices, episode = student.sequence_window_indices(np.array([30, 50]), 16, 2, 8)
    assert isinstance(indices, np.ndarray) and isinstance(episode, np.ndarray)
    assert indices.ndim == 2 and indices.shape[1] == 16, f"indices shape {indices.shape}, expected (W, 16)"
    assert episode.shape == (indices.shape[0],), f"episode shape {episode.shape}, expected ({indices.shape[0]},)"
    assert indices.dtype == np.int64 and episode.dtype == np.int64


def test_one_episode_matches_definition(student):
    for horizon, to, ta in [(16, 2, 8), (10, 1, 1), (8, 3, 4), (5, 2, 4)]:
        indices, episode = student.sequence_window_indices(np.array([40]), horizon, to, ta)
        want, want_ep = brute_force([40], horizon, to, ta)
        np.testing.assert_array_equal(indices, want, err_msg=f"Tp={horizon}, To={to}, Ta={ta}")
        np.testing.assert_array_equal(episode, want_ep)


def test_edge_padding(student):
    to, ta, horizon = 3, 5, 12
    indices, _ = student.sequence_window_indices(np.array([20]), horizon, to, ta)
    # the first window starts To - 1 steps early: those steps repeat row 0, then 0, 1, 2, ...
    np.testing.assert_array_equal(indices[0], np.r_[[0] * (to - 1), np.arange(horizon - to + 1)])
    # the last window runs Ta - 1 steps past the end: those repeat the last row (19)
    np.testing.assert_array_equal(indices[-1, -ta:], [19] * ta)
    assert indices.min() == 0 and indices.max() == 19


def test_windows_stay_in_their_episode(student):
    ends = np.array([7, 25, 26, 60])
    starts = np.r_[0, ends[:-1]]
    indices, episode = student.sequence_window_indices(ends, 16, 2, 8)
    np.testing.assert_array_equal(np.unique(episode), np.arange(len(ends)))
    assert np.all(np.diff(episode) >= 0), "windows must be grouped by episode, in order"
    assert np.all(indices >= starts[episode][:, None]), "a window reaches into the previous episode"
    assert np.all(indices < ends[episode][:, None]), "a window reaches into the next episode"
    # inside an episode consecutive steps are consecutive rows or a repeated (padded) row
    steps = np.diff(indices, axis=1)
    assert np.all((steps == 0) | (steps == 1))


def test_window_count(student):
    ends = np.array([30, 70, 100])
    lengths = np.diff(np.r_[0, ends])
    for horizon, to, ta in [(16, 2, 8), (12, 4, 2), (6, 1, 6)]:
        _, episode = student.sequence_window_indices(ends, horizon, to, ta)
        counts = np.bincount(episode, minlength=len(ends))
        np.testing.assert_array_equal(counts, np.maximum(lengths - horizon + to + ta - 1, 1),
                                      err_msg=f"Tp={horizon}, To={to}, Ta={ta}")


def test_short_episode_gets_one_window(student):
    indices, episode = student.sequence_window_indices(np.array([3, 40]), 16, 2, 8)
    np.testing.assert_array_equal(episode == 0, np.arange(len(episode)) == 0)
    np.testing.assert_array_equal(indices[0], np.r_[0, 0, 1, [2] * 13])


@pytest.mark.parametrize("seed", range(3))
def test_matches_library_on_random_datasets(student, seed):
    rng = np.random.default_rng(seed)
    for _ in range(20):
        ends = np.cumsum(rng.integers(1, 30, size=rng.integers(1, 5)))
        horizon = int(rng.integers(1, 17))
        to = int(rng.integers(1, horizon + 1))
        ta = int(rng.integers(1, horizon - to + 2))
        indices, episode = student.sequence_window_indices(ends, horizon, to, ta)
        ref = SequenceWindows.build(ends, horizon, to, ta)
        np.testing.assert_array_equal(indices, ref.indices, err_msg=f"ends={ends}, Tp={horizon}, To={to}, Ta={ta}")
        np.testing.assert_array_equal(episode, ref.episode)
        want, want_ep = brute_force(ends, horizon, to, ta)
        np.testing.assert_array_equal(indices, want)
