"""Batchers resume exactly: a saved shuffling state gives the batches an uninterrupted run would draw."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coursekit.data.batches import ChunkBatcher, EpochSampler, WindowBatcher


def _reference_epochs(n: int, b: int, seed: int, batches: int) -> list[torch.Tensor]:
    """The defining rule, written out: fresh permutations, full batches only."""
    g, out = torch.Generator().manual_seed(seed), []
    while len(out) < batches:
        perm = torch.randperm(n, generator=g)
        out += [perm[s : s + b] for s in range(0, n - b + 1, b)]
    return out[:batches]


@pytest.mark.parametrize("n,b", [(10, 3), (12, 4), (5, 8), (1, 1)])
def test_sampler_draws_the_defining_sequence(n, b):
    sampler = EpochSampler(n, b, torch.Generator().manual_seed(7))
    got = [sampler.next_indices() for _ in range(9)]
    want = _reference_epochs(n, min(b, n), 7, 9)
    assert all(torch.equal(x, y) for x, y in zip(got, want))


@pytest.mark.parametrize("cut", [0, 1, 3, 4, 7])  # mid-epoch and at epoch boundaries (10 // 3 = 3 per epoch)
def test_sampler_resumed_from_its_state_continues_exactly(cut):
    whole = EpochSampler(10, 3, torch.Generator().manual_seed(1))
    want = [whole.next_indices() for _ in range(12)]
    first = EpochSampler(10, 3, torch.Generator().manual_seed(1))
    _ = [first.next_indices() for _ in range(cut)]
    state = first.state_dict()
    resumed = EpochSampler(10, 3, torch.Generator().manual_seed(999))  # another seed: the state must win
    resumed.load_state_dict(state)
    assert all(torch.equal(resumed.next_indices(), w) for w in want[cut:])


def test_state_of_another_shape_is_refused():
    state = EpochSampler(10, 3, torch.Generator()).state_dict()
    with pytest.raises(ValueError, match="n=10, batch_size=3; this sampler has n=11, batch_size=3"):
        EpochSampler(11, 3, torch.Generator()).load_state_dict(state)


def _window_batcher(seed: int) -> WindowBatcher:
    rng = np.random.default_rng(0)
    return WindowBatcher({"obs": rng.normal(size=(30, 4))}, rng.normal(size=(30, 2)), np.array([12, 30]),
                         horizon=8, n_obs_steps=2, n_action_steps=4, batch_size=5, seed=seed)


def _chunk_batcher(seed: int) -> ChunkBatcher:
    rng = np.random.default_rng(0)
    return ChunkBatcher({"obs": rng.normal(size=(30, 4))}, rng.normal(size=(30, 2)), np.array([12, 30]),
                        chunk_size=6, batch_size=5, seed=seed)


@pytest.mark.parametrize("make", [_window_batcher, _chunk_batcher])
def test_batchers_resume_exactly(make):
    want = [b for _, b in zip(range(10), make(0))]
    first = make(0)
    it = iter(first)
    _ = [next(it) for _ in range(4)]
    resumed = make(3)
    resumed.load_state_dict(first.state_dict())
    got = [b for _, b in zip(range(6), resumed)]
    for g, w in zip(got, want[4:]):
        assert g.keys() == w.keys() and all(torch.equal(g[k], w[k]) for k in g)
