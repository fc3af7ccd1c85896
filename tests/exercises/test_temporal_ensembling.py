"""Exercise 8.1 (temporal_ensembling): ACT's temporal ensembling executor.

Reference: the defining formula a_t = sum_i w_i pred_i / sum_i w_i, w_i = exp(-m i), written as
plain loops over hand-built (seeded) chunk streams.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

EXERCISE = "temporal_ensembling"


class Stream:
    """A chunk predictor returning pre-drawn chunks (n_calls, B, Tp, Da), one per call."""

    def __init__(self, n_calls: int, B: int, Tp: int, Da: int, seed: int):
        self.chunks = np.random.default_rng(seed).normal(size=(n_calls, B, Tp, Da))
        self.n = 0

    def __call__(self, history):
        self.n += 1
        return self.chunks[self.n - 1]


def expected(chunks: np.ndarray, t: int, m: float, newest_first: bool, start: int = 0) -> np.ndarray:
    k = chunks.shape[2] - start
    made_at = [s for s in range(t + 1) if t - s < k]  # oldest first
    if newest_first:
        made_at = made_at[::-1]
    w = [math.exp(-m * i) for i in range(len(made_at))]
    return sum(wi * chunks[s, :, start + t - s] for wi, s in zip(w, made_at)) / sum(w)


def _run(student, stream, T, B, Do=3, **kwargs):
    ex = student.TemporalEnsemble(stream, **kwargs)
    ex.reset(np.zeros((B, Do)))
    return [np.asarray(ex.act(np.full((B, Do), float(t)))) for t in range(T)]


def test_first_step_is_the_first_chunk(student):
    stream = Stream(1, 2, 4, 3, seed=0)
    (a,) = _run(student, stream, 1, 2)
    assert a.shape == (2, 3), f"act must return (B, Da) = (2, 3), got {a.shape}"
    np.testing.assert_allclose(a, stream.chunks[0, :, 0], atol=1e-12, err_msg="at t = 0 only one prediction exists")


def test_plain_mean_when_m_is_zero(student):
    stream = Stream(7, 2, 4, 2, seed=1)
    acts = _run(student, stream, 7, 2, ensemble_decay=0.0)
    for t in range(7):
        np.testing.assert_allclose(acts[t], expected(stream.chunks, t, 0.0, False), atol=1e-12,
                                   err_msg=f"t={t}: with m = 0 the action is the mean of every chunk covering t")


@pytest.mark.parametrize("m", [0.01, 0.7])
def test_oldest_first_weights(student, m):
    stream = Stream(10, 3, 5, 2, seed=2)
    acts = _run(student, stream, 10, 3, ensemble_decay=m)
    for t in range(10):
        np.testing.assert_allclose(acts[t], expected(stream.chunks, t, m, False), atol=1e-10,
                                   err_msg=f"t={t}, m={m}: w_i = exp(-m i), i = 0 the OLDEST chunk, normalised")


@pytest.mark.parametrize("m", [0.01, 0.7])
def test_newest_first_weights(student, m):
    stream = Stream(10, 2, 5, 2, seed=3)
    acts = _run(student, stream, 10, 2, ensemble_decay=m, newest_first=True)
    for t in range(10):
        np.testing.assert_allclose(acts[t], expected(stream.chunks, t, m, True), atol=1e-10,
                                   err_msg=f"t={t}, m={m}: with newest_first, i = 0 is the NEWEST chunk")


def test_old_chunks_expire(student):
    stream = Stream(9, 1, 3, 1, seed=4)
    acts = _run(student, stream, 9, 1, ensemble_decay=0.0)
    t = 8
    np.testing.assert_allclose(acts[t], stream.chunks[[6, 7, 8], :, [2, 1, 0]].mean(axis=0), atol=1e-12,
                               err_msg="a chunk of k steps made at s only covers s .. s+k-1")


def test_start_offset_for_diffusion_policy(student):
    stream = Stream(6, 2, 6, 1, seed=5)
    acts = _run(student, stream, 6, 2, n_obs_steps=2, ensemble_decay=0.3)
    for t in range(6):
        np.testing.assert_allclose(acts[t], expected(stream.chunks, t, 0.3, False, start=1), atol=1e-10,
                                   err_msg=f"t={t}: read each chunk from index self.start (= To - 1) on")
