"""Temporal ensembling against its defining formula on hand-built chunk streams."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coursekit.execution.ensembling import TemporalEnsemble


class Stream:
    """A chunk predictor that returns pre-drawn chunks, one per call, and records its inputs."""

    def __init__(self, n_calls: int, B: int, k: int, Da: int, seed: int = 0):
        self.chunks = np.random.default_rng(seed).normal(size=(n_calls, B, k, Da))
        self.calls: list[np.ndarray] = []

    def __call__(self, history):
        self.calls.append(np.array(history))
        return self.chunks[len(self.calls) - 1]


def expected_action(chunks: np.ndarray, t: int, m: float, newest_first: bool, start: int = 0) -> np.ndarray:
    """The defining formula, written as loops: a_t = sum_i w_i pred_i / sum_i w_i, w_i = exp(-m i)."""
    k = chunks.shape[2] - start
    made_at = [s for s in range(t + 1) if t - s < k]  # chunks covering t, oldest first
    if newest_first:
        made_at = made_at[::-1]
    num, den = 0.0, 0.0
    for i, s in enumerate(made_at):
        w = math.exp(-m * i)
        num = num + w * chunks[s, :, start + t - s]
        den += w
    return num / den


@pytest.mark.parametrize("newest_first", [False, True])
@pytest.mark.parametrize("m", [0.0, 0.01, 0.5])
def test_matches_defining_formula(m, newest_first):
    B, k, Da, T = 3, 5, 2, 12
    stream = Stream(T, B, k, Da, seed=7)
    ex = TemporalEnsemble(stream, n_obs_steps=1, ensemble_decay=m, newest_first=newest_first)
    ex.reset(np.zeros((B, 4)))
    for t in range(T):
        got = ex.act(np.full((B, 4), float(t)))
        assert got.shape == (B, Da)
        np.testing.assert_allclose(got, expected_action(stream.chunks, t, m, newest_first), atol=1e-12)


def test_weightings_differ_and_order_matters():
    """Oldest-first and newest-first disagree once two chunks overlap (the test can fail)."""
    B, k, Da = 1, 4, 1
    stream_a, stream_b = Stream(3, B, k, Da, seed=1), Stream(3, B, k, Da, seed=1)
    old = TemporalEnsemble(stream_a, ensemble_decay=1.0, newest_first=False)
    new = TemporalEnsemble(stream_b, ensemble_decay=1.0, newest_first=True)
    for ex in (old, new):
        ex.reset(np.zeros((B, 2)))
    outs = [(old.act(np.zeros((B, 2))), new.act(np.zeros((B, 2)))) for _ in range(3)]
    np.testing.assert_allclose(outs[0][0], outs[0][1])  # one chunk: identical
    assert not np.allclose(outs[2][0], outs[2][1])
    # with a large decay, oldest-first follows the oldest chunk, newest-first the newest
    c = stream_a.chunks
    steep_old = TemporalEnsemble(Stream(3, B, k, Da, seed=1), ensemble_decay=50.0)
    steep_new = TemporalEnsemble(Stream(3, B, k, Da, seed=1), ensemble_decay=50.0, newest_first=True)
    for ex in (steep_old, steep_new):
        ex.reset(np.zeros((B, 2)))
        acts = [ex.act(np.zeros((B, 2))) for _ in range(3)]
        ref = c[0, :, 2] if ex is steep_old else c[2, :, 0]
        np.testing.assert_allclose(acts[2], ref, atol=1e-12)


def test_chunks_expire_after_k_steps():
    """At t >= k exactly k chunks cover t: the one made at t - k no longer counts."""
    B, k, Da, T = 1, 3, 1, 8
    stream = Stream(T, B, k, Da, seed=3)
    ex = TemporalEnsemble(stream, ensemble_decay=0.0)
    ex.reset(np.zeros((B, 1)))
    for t in range(T):
        a = ex.act(np.zeros((B, 1)))
    t = T - 1
    mean = np.mean([stream.chunks[s, :, t - s] for s in range(t - k + 1, t + 1)], axis=0)
    np.testing.assert_allclose(a, mean, atol=1e-12)


def test_batch_is_independent_envs():
    B, k, Da, T = 3, 4, 2, 6
    stream = Stream(T, B, k, Da, seed=5)
    ex = TemporalEnsemble(stream, ensemble_decay=0.3)
    ex.reset(np.zeros((B, 2)))
    batched = [ex.act(np.zeros((B, 2))) for _ in range(T)]
    for b in range(B):
        one_env = Stream(T, 1, k, Da)
        one_env.chunks = stream.chunks[:, b:b + 1]  # the same chunks, env b only
        single = TemporalEnsemble(one_env, ensemble_decay=0.3)
        single.reset(np.zeros((1, 2)))
        for t in range(T):
            np.testing.assert_allclose(single.act(np.zeros((1, 2))), batched[t][b:b + 1], atol=1e-12)


def test_observation_history_and_start_for_diffusion_policy():
    """To = 2: the history repeats the first observation; chunks are read from start = To - 1."""
    B, Tp, Da, T = 2, 6, 1, 5
    stream = Stream(T, B, Tp, Da, seed=9)
    ex = TemporalEnsemble(stream, n_obs_steps=2, ensemble_decay=0.01)
    obs = [np.full((B, 3), float(t)) for t in range(T)]
    ex.reset(obs[0])
    for t in range(T):
        got = ex.act(obs[t])
        np.testing.assert_allclose(got, expected_action(stream.chunks, t, 0.01, False, start=1), atol=1e-12)
    assert stream.calls[0].shape == (B, 2, 3)
    np.testing.assert_array_equal(stream.calls[0][:, 0], obs[0])  # padded with the first obs
    np.testing.assert_array_equal(stream.calls[3][:, 0], obs[2])
    np.testing.assert_array_equal(stream.calls[3][:, 1], obs[3])


def test_torch_predictor_and_reset_forgets():
    torch = pytest.importorskip("torch")
    ex = TemporalEnsemble(lambda h: torch.ones(h.shape[0], 4, 2) * float(h[0, -1, 0]), ensemble_decay=0.0)
    ex.reset(np.zeros((1, 1)))
    ex.act(np.full((1, 1), 1.0))
    a = ex.act(np.full((1, 1), 3.0))
    np.testing.assert_allclose(a, [[2.0, 2.0]])  # mean of 1 and 3
    ex.reset(np.zeros((1, 1)))
    np.testing.assert_allclose(ex.act(np.full((1, 1), 5.0)), [[5.0, 5.0]])


def test_bad_arguments():
    with pytest.raises(ValueError, match="ensemble_decay"):
        TemporalEnsemble(lambda h: h, ensemble_decay=-1.0)
    with pytest.raises(ValueError, match="n_obs_steps"):
        TemporalEnsemble(lambda h: h, n_obs_steps=0)
    ex = TemporalEnsemble(lambda h: np.zeros((1, 3, 1)))
    with pytest.raises(ValueError, match="before reset"):
        ex.act(np.zeros((1, 2)))
    ex.reset(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="shape"):
        ex.act(np.zeros((2, 2)))
