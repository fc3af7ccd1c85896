"""The two-route toy chunks of chapters 2-4: shapes, sides, determinism and the [-1, 1] scaling."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coursekit.data.two_routes import TWO_ROUTE_SCENE, pixels_to_unit, route_chunks, unit_to_pixels


def test_two_routes_round_the_block():
    chunks, side = route_chunks(400, np.random.default_rng(0))
    assert chunks.shape == (400, 16, 2) and side.shape == (400,)
    assert set(np.unique(side)) == {-1.0, 1.0} and 0.4 < (side < 0).mean() < 0.6
    mid_x = chunks[:, 8, 0]  # halfway along: clearly on the chunk's own side of the block
    assert np.all((mid_x < TWO_ROUTE_SCENE[2] - 80) == (side < 0)) and np.all((mid_x > TWO_ROUTE_SCENE[2] + 80) == (side > 0))
    assert np.allclose(chunks[:, 0], TWO_ROUTE_SCENE[:2], atol=25)  # every route starts at the pusher
    again, _ = route_chunks(400, np.random.default_rng(0))
    assert np.array_equal(chunks, again)


def test_biased_sides_and_horizon():
    _, side = route_chunks(2000, np.random.default_rng(1), horizon=8, p_left=0.8)
    assert abs((side < 0).mean() - 0.8) < 0.03
    with pytest.raises(ValueError, match="p_left"):
        route_chunks(4, np.random.default_rng(0), p_left=1.5)
    with pytest.raises(ValueError, match="n must be"):
        route_chunks(0, np.random.default_rng(0))


def test_unit_scaling_round_trip():
    px = np.array([[0.0, 512.0], [256.0, 128.0]])
    x = pixels_to_unit(px)
    assert x.dtype == torch.float32 and torch.allclose(x, torch.tensor([[-1.0, 1.0], [0.0, -0.5]]))
    assert np.allclose(unit_to_pixels(x), px) and np.allclose(unit_to_pixels(x.numpy()), px)
