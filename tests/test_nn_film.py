"""FiLM against its closed form."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from coursekit.nn import FiLM


def test_film_closed_form():
    torch.manual_seed(0)
    film = FiLM(cond_dim=5, channels=3)
    h, cond = torch.randn(4, 3, 7), torch.randn(4, 5)
    W, b = film.linear.weight, film.linear.bias
    assert W.shape == (6, 5) and b.shape == (6,)
    e = F.mish(cond) @ W.T + b  # (4, 6)
    expected = e[:, :3, None] * h + e[:, 3:, None]
    torch.testing.assert_close(film(h, cond), expected)


def test_film_identity_when_scale_one_bias_zero():
    film = FiLM(2, 4)
    with torch.no_grad():
        film.linear.weight.zero_()
        film.linear.bias.copy_(torch.tensor([1.0] * 4 + [0.0] * 4))
    h = torch.randn(3, 4, 6)
    torch.testing.assert_close(film(h, torch.randn(3, 2)), h)


def test_film_bad_shapes():
    film = FiLM(2, 4)
    with pytest.raises(ValueError, match=r"\(B, 4, L\)"):
        film(torch.randn(3, 5, 6), torch.randn(3, 2))
    with pytest.raises(ValueError, match="cond"):
        film(torch.randn(3, 4, 6), torch.randn(3, 3))
    with pytest.raises(ValueError, match="channels"):
        FiLM(2, 0)
