"""Normalisers: closed forms, round trips on numpy and torch, and their checkpoint state."""

from __future__ import annotations

import numpy as np
import pytest

from coursekit.data import MeanStdNormalizer, MinMaxNormalizer, normalizer_from_state


def test_minmax_maps_range_to_unit_interval():
    data = np.array([[0.0, 10.0, 3.0], [4.0, 30.0, 3.0], [2.0, 20.0, 3.0]])
    norm = MinMaxNormalizer.fit(data)
    out = norm.normalize(data)
    np.testing.assert_allclose(out[:, 0], [-1, 1, 0], atol=1e-6)
    np.testing.assert_allclose(out[:, 1], [-1, 1, 0], atol=1e-6)
    np.testing.assert_allclose(out[:, 2], 0.0, atol=1e-6)  # a constant dimension maps to 0
    np.testing.assert_allclose(norm.unnormalize(out), data, atol=1e-5)


def test_meanstd_clips_small_std():
    data = np.array([[1.0, 5.0], [3.0, 5.0]])
    norm = MeanStdNormalizer.fit(data)
    np.testing.assert_allclose(norm.std, [1.0, 0.01])
    np.testing.assert_allclose(norm.normalize(data), [[-1, 0], [1, 0]], atol=1e-6)


@pytest.mark.parametrize("cls", [MinMaxNormalizer, MeanStdNormalizer])
def test_torch_round_trip_and_state(cls):
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(0)
    data = rng.normal(size=(50, 4)) * [1, 10, 100, 0.1]
    norm = cls.fit(data)
    x = torch.tensor(data[:5], dtype=torch.float32)
    y = norm.normalize(x)
    assert isinstance(y, torch.Tensor)
    np.testing.assert_allclose(y.numpy(), norm.normalize(data[:5].astype(np.float32)), rtol=1e-5, atol=1e-5)
    back = normalizer_from_state(cls.kind, norm.state_dict())
    np.testing.assert_allclose(back.unnormalize(y).numpy(), data[:5], rtol=1e-4, atol=1e-4)


def test_dimension_mismatch_is_named():
    norm = MinMaxNormalizer.fit(np.zeros((3, 2)) + [[0, 1]])
    with pytest.raises(ValueError, match="last dimension 3"):
        norm.normalize(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="unknown normaliser kind 'zscore'"):
        normalizer_from_state("zscore", {})
    with pytest.raises(ValueError, match="finite"):
        MinMaxNormalizer(np.array([0.0, np.nan]), np.array([1.0, 1.0]))
