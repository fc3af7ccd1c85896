"""The conditional 1-D U-Net: shapes, conditioning, sizes, and the FiLM plug-in."""

from __future__ import annotations

import pytest
import torch

from coursekit.nn import FiLM, ConditionalUnet1D, SinusoidalPosEmb, UNet1DConfig

SMALL = UNet1DConfig(down_dims=(16, 32, 64), diffusion_step_embed_dim=16)


def _n_params(m):
    return sum(p.numel() for p in m.parameters())


def test_output_shape_and_timestep_forms():
    torch.manual_seed(0)
    net = ConditionalUnet1D(input_dim=2, global_cond_dim=12, config=SMALL)
    x, cond = torch.randn(3, 16, 2), torch.randn(3, 12)
    out = net(x, torch.tensor([0, 5, 99]), cond)
    assert out.shape == (3, 16, 2)
    # A scalar timestep broadcasts to the batch.
    torch.testing.assert_close(net(x, 7, cond), net(x, torch.full((3,), 7), cond))
    assert net(torch.randn(2, 8, 2), 3, torch.randn(2, 12)).shape == (2, 8, 2)


def test_conditioning_and_timestep_change_the_output():
    torch.manual_seed(1)
    net = ConditionalUnet1D(input_dim=2, global_cond_dim=4, config=SMALL).eval()
    x = torch.randn(2, 16, 2)
    cond = torch.randn(1, 4).expand(2, 4)
    base = net(x, 10, cond)
    assert not torch.allclose(base, net(x, 10, cond + 1.0), atol=1e-4)
    assert not torch.allclose(base, net(x, 60, cond), atol=1e-4)
    # Samples are processed independently: same input and condition -> same output row.
    x_same = x[:1].expand(2, 16, 2)
    out = net(x_same, 10, cond)
    torch.testing.assert_close(out[0], out[1])


def test_parameter_counts_cpu_default_and_paper():
    assert 4.0e6 < _n_params(ConditionalUnet1D(2, 12)) < 5.0e6  # reference: about 4-5 M
    paper = ConditionalUnet1D(2, 40, UNet1DConfig.preset("paper_lowdim"))  # 20-d keypoints x To = 2
    assert _n_params(paper) == pytest.approx(65.8e6, rel=0.01)


def test_film_cls_is_used_everywhere():
    built = []

    class CountingFiLM(FiLM):
        def __init__(self, cond_dim, channels):
            super().__init__(cond_dim, channels)
            built.append((cond_dim, channels))

    ConditionalUnet1D(2, 6, SMALL, film_cls=CountingFiLM)
    # 3 down levels x 2 + 2 mid + 2 up levels x 2 residual blocks, each with one FiLM.
    assert len(built) == 12 and all(c == 16 + 6 for c, _ in built)


def test_sinusoidal_embedding_closed_form():
    emb = SinusoidalPosEmb(8)(torch.tensor([0.0, 3.0]))
    freqs = torch.exp(torch.arange(4) * -(torch.log(torch.tensor(10000.0)) / 3))
    torch.testing.assert_close(emb[1], torch.cat([torch.sin(3 * freqs), torch.cos(3 * freqs)]))
    torch.testing.assert_close(emb[0], torch.tensor([0.0] * 4 + [1.0] * 4))


def test_bad_inputs_raise():
    net = ConditionalUnet1D(2, 4, SMALL)
    with pytest.raises(ValueError, match="Tp=10"):
        net(torch.randn(1, 10, 2), 0, torch.randn(1, 4))
    with pytest.raises(ValueError, match="global_cond"):
        net(torch.randn(1, 16, 2), 0, None)
    with pytest.raises(ValueError, match=r"\(B, Tp, 2\)"):
        net(torch.randn(1, 16, 3), 0, torch.randn(1, 4))
    with pytest.raises(ValueError, match="n_groups"):
        UNet1DConfig(down_dims=(12, 24), n_groups=8)
    with pytest.raises(ValueError, match="kernel_size"):
        UNet1DConfig(kernel_size=4)
    with pytest.raises(ValueError, match="preset"):
        UNet1DConfig.preset("huge")
