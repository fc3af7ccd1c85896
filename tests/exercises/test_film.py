"""Exercise 3.1 (film): the FiLM layer. References: the closed form written here, torch's Mish."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F
from torch import nn

from coursekit.nn.unet1d import ConditionalUnet1D, UNet1DConfig

EXERCISE = "film"


def _film(student, cond_dim, channels, seed=0):
    torch.manual_seed(seed)
    return student.FiLM(cond_dim, channels)


def test_film_has_one_linear_layer_of_the_right_size(student):
    film = _film(student, 5, 3)
    assert isinstance(getattr(film, "linear", None), nn.Linear), "create self.linear = nn.Linear(cond_dim, 2 * channels)"
    assert film.linear.in_features == 5 and film.linear.out_features == 6, (
        f"self.linear is {film.linear.in_features} -> {film.linear.out_features}, expected 5 -> 6 (2 * channels)")
    n = sum(p.numel() for p in film.parameters())
    assert n == 5 * 6 + 6, f"FiLM(5, 3) has {n} parameters, expected 36 (one Linear(5, 6))"


@pytest.mark.parametrize("cond_dim,channels,length", [(5, 3, 7), (1, 8, 1), (12, 4, 16)])
def test_film_matches_closed_form(student, cond_dim, channels, length):
    film = _film(student, cond_dim, channels, seed=cond_dim)
    g = torch.Generator().manual_seed(channels)
    h, cond = torch.randn(4, channels, length, generator=g), torch.randn(4, cond_dim, generator=g)
    with torch.no_grad():
        film.linear.weight.copy_(torch.randn(2 * channels, cond_dim, generator=g))
        film.linear.bias.copy_(torch.randn(2 * channels, generator=g))
    e = F.mish(cond) @ film.linear.weight.T + film.linear.bias  # (4, 2C)
    want = e[:, :channels, None] * h + e[:, channels:, None]
    got = film(h, cond)
    assert got.shape == h.shape, f"shape {tuple(got.shape)}, expected (B, C, L) = {tuple(h.shape)}"
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-6,
                               msg=lambda m: f"out must be scale * h + bias with [scale | bias] = linear(mish(cond)): {m}")


def test_film_scale_first_then_bias(student):
    film = _film(student, 2, 3)
    with torch.no_grad():
        film.linear.weight.zero_()
        film.linear.bias.copy_(torch.tensor([2.0, 2.0, 2.0, 1.0, 1.0, 1.0]))
    h = torch.ones(1, 3, 4)
    got = film(h, torch.zeros(1, 2))
    torch.testing.assert_close(got, torch.full((1, 3, 4), 3.0),
                               msg=lambda m: f"first C outputs scale, last C add (2 * 1 + 1 = 3): {m}")


def test_film_uses_mish_on_the_condition(student):
    film = _film(student, 1, 1)
    with torch.no_grad():
        film.linear.weight.copy_(torch.tensor([[1.0], [0.0]]))
        film.linear.bias.zero_()
    cond = torch.tensor([[-1.0], [2.0]])
    got = film(torch.ones(2, 1, 1), cond)
    torch.testing.assert_close(got.reshape(2), F.mish(cond).reshape(2),
                               msg=lambda m: f"scale must be linear(mish(cond)), not linear(cond): {m}")


def test_film_plugs_into_the_unet(student):
    torch.manual_seed(0)
    net = ConditionalUnet1D(2, 4, UNet1DConfig(down_dims=(8, 16), diffusion_step_embed_dim=8),
                            film_cls=student.FiLM).eval()
    x = torch.randn(2, 8, 2)
    out_a = net(x, 5, torch.zeros(2, 4))
    out_b = net(x, 5, torch.ones(2, 4))
    assert out_a.shape == (2, 8, 2) and torch.isfinite(out_a).all()
    assert not torch.allclose(out_a, out_b), "the condition must change the U-Net's output through FiLM"
