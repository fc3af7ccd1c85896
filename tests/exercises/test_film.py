"""Exercise 3.1 (film): the FiLM layer. References: the closed form written here, torch's Mish,
and the library's ConditionalUnet1D with its own FiLM (loaded with the student's weights).

The layer lives in the worker: the tests build it there (``student.FiLM``), set its weights
(``sandbox.load_state_dict``), run it, and read its parameters and gradients as tensors.
"""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from coursekit.grading.compare import assert_close
from coursekit.nn.unet1d import ConditionalUnet1D, UNet1DConfig

EXERCISE = "film"


def _film(student, sandbox, cond_dim, channels, seed=0):
    sandbox.seed(seed)
    return student.FiLM(cond_dim, channels)


def test_film_has_one_linear_layer_of_the_right_size(student, sandbox):
    film = _film(student, sandbox, 5, 3)
    params = sandbox.parameters(film)
    assert set(params) == {"linear.weight", "linear.bias"}, (
        f"FiLM's parameters are {sorted(params)}, expected exactly self.linear's weight and bias")
    weight = params["linear.weight"]
    assert tuple(weight.shape) == (6, 5), (
        f"self.linear.weight has shape {tuple(weight.shape)}, expected (2 * channels, cond_dim) = (6, 5)")
    assert tuple(params["linear.bias"].shape) == (6,), "self.linear.bias must have 2 * channels = 6 entries"


def _closed_form(h, cond, weight, bias):
    e = F.mish(cond) @ weight.T + bias  # (B, 2C)
    channels = h.shape[1]
    return e[:, :channels, None] * h + e[:, channels:, None]  # (B, C, L)


@pytest.mark.parametrize("cond_dim,channels,length", [(5, 3, 7), (1, 8, 1), (12, 4, 16)])
def test_film_matches_closed_form(student, sandbox, cond_dim, channels, length):
    film = _film(student, sandbox, cond_dim, channels, seed=cond_dim)
    g = torch.Generator().manual_seed(channels)
    h, cond = torch.randn(4, channels, length, generator=g), torch.randn(4, cond_dim, generator=g)
    weight, bias = torch.randn(2 * channels, cond_dim, generator=g), torch.randn(2 * channels, generator=g)
    sandbox.load_state_dict(film, {"linear.weight": weight, "linear.bias": bias})
    got = film(h, cond)
    want = _closed_form(h, cond, weight, bias)
    assert tuple(got.shape) == tuple(h.shape), f"output shape {tuple(got.shape)}, expected (B, C, L) = {tuple(h.shape)}"
    assert_close(got, want, rtol=1e-5, atol=1e-6,
                               msg=lambda m: f"the output differs from scale * h + bias, [scale | bias] = linear(mish(cond)): {m}")
    # gradients computed in the worker against autograd through the closed form here
    seed = torch.randn(got.shape, generator=g)
    _, (g_h, g_cond, g_params) = sandbox.grad(film, h, cond, wrt=(0, 1, film), grad_output=seed)
    leaves = [h.clone().requires_grad_(True), cond.clone().requires_grad_(True),
              weight.clone().requires_grad_(True), bias.clone().requires_grad_(True)]
    ref = torch.autograd.grad(_closed_form(*leaves), leaves, seed)
    for name, a, b in [("h", g_h, ref[0]), ("cond", g_cond, ref[1]), ("linear.weight", g_params.get("linear.weight"), ref[2]),
                       ("linear.bias", g_params.get("linear.bias"), ref[3])]:
        assert a is not None, f"no gradient reached {name}: keep the forward pass in torch operations"
        assert_close(a, b, rtol=1e-4, atol=1e-5, msg=lambda m, n=name: f"the gradient with respect to {n} differs: {m}")


def test_film_scale_first_then_bias(student, sandbox):
    film = _film(student, sandbox, 2, 3)
    sandbox.load_state_dict(film, {"linear.weight": torch.zeros(6, 2),
                                   "linear.bias": torch.tensor([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])})
    got = film(torch.ones(1, 3, 4), torch.zeros(1, 2))
    assert_close(got, torch.full((1, 3, 4), 3.0),
                               msg=lambda m: f"with scales 2 and biases 1 the output must be 2 * 1 + 1 = 3 (first C outputs scale, last C add): {m}")


def test_film_uses_mish_on_the_condition(student, sandbox):
    film = _film(student, sandbox, 1, 1)
    sandbox.load_state_dict(film, {"linear.weight": torch.tensor([[1.0], [0.0]]), "linear.bias": torch.zeros(2)})
    cond = torch.tensor([[-1.0], [2.0]])
    got = film(torch.ones(2, 1, 1), cond)
    assert_close(got.reshape(2), F.mish(cond).reshape(2),
                               msg=lambda m: f"the scale must be linear(mish(cond)), not linear(cond): {m}")


def test_film_plugs_into_the_unet(student, sandbox):
    config = dict(down_dims=(8, 16), diffusion_step_embed_dim=8)
    sandbox.seed(0)
    net = sandbox.new("coursekit.nn.unet1d:ConditionalUnet1D", 2, 4,
                      sandbox.new("coursekit.nn.unet1d:UNet1DConfig", **config), film_cls=student.FiLM)
    net.eval()
    x = torch.randn(2, 8, 2, generator=torch.Generator().manual_seed(1))
    out_a, out_b = net(x, 5, torch.zeros(2, 4)), net(x, 5, torch.ones(2, 4))
    assert tuple(out_a.shape) == (2, 8, 2) and torch.isfinite(out_a).all(), \
        f"the U-Net with your FiLM gives shape {tuple(out_a.shape)}, expected (2, 8, 2), all finite"
    # the same weights in the library's U-Net with the reference FiLM must give the same output
    reference = ConditionalUnet1D(2, 4, UNet1DConfig(**config)).eval()
    reference.load_state_dict(sandbox.state_dict(net))
    with torch.no_grad():
        want = reference(x, 5, torch.ones(2, 4))
    assert_close(out_b, want, rtol=1e-4, atol=1e-5,
                               msg=lambda m: f"the U-Net's output with your FiLM differs from the reference FiLM's: {m}")
    assert not torch.allclose(out_a, out_b), "the condition must change the U-Net's output through FiLM"
