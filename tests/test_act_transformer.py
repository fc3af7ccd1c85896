"""ACT's transformer layers against torch's own post-norm layers, and the sine position tables."""

from __future__ import annotations

import math

import pytest

torch = pytest.importorskip("torch")
from torch import nn  # noqa: E402

from coursekit.nn.act_transformer import ACTTransformer, DecoderLayer, EncoderLayer  # noqa: E402
from coursekit.nn.positional import sinusoidal_1d, sinusoidal_2d  # noqa: E402

D, H, FF = 16, 4, 32


def _copy_encoder(ours: EncoderLayer, ref: nn.TransformerEncoderLayer) -> None:
    ref.self_attn.load_state_dict(ours.self_attn.state_dict())
    ref.linear1.load_state_dict(ours.ff.net[0].state_dict())
    ref.linear2.load_state_dict(ours.ff.net[3].state_dict())
    ref.norm1.load_state_dict(ours.norm1.state_dict())
    ref.norm2.load_state_dict(ours.norm2.state_dict())


def test_encoder_layer_is_torch_post_norm_layer_without_positions():
    torch.manual_seed(0)
    ours = EncoderLayer(D, H, FF, dropout=0.0).eval()
    ref = nn.TransformerEncoderLayer(D, H, FF, dropout=0.0, activation="relu", batch_first=True, norm_first=False).eval()
    _copy_encoder(ours, ref)
    x = torch.randn(3, 7, D)
    mask = torch.zeros(3, 7, dtype=torch.bool)
    mask[:, -2:] = True
    torch.testing.assert_close(ours(x), ref(x), rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(ours(x, key_padding_mask=mask)[:, :5], ref(x, src_key_padding_mask=mask)[:, :5],
                               rtol=1e-5, atol=1e-5)


def test_decoder_layer_is_torch_post_norm_layer_without_positions():
    torch.manual_seed(1)
    ours = DecoderLayer(D, H, FF, dropout=0.0).eval()
    ref = nn.TransformerDecoderLayer(D, H, FF, dropout=0.0, activation="relu", batch_first=True, norm_first=False).eval()
    ref.self_attn.load_state_dict(ours.self_attn.state_dict())
    ref.multihead_attn.load_state_dict(ours.cross_attn.state_dict())
    ref.linear1.load_state_dict(ours.ff.net[0].state_dict())
    ref.linear2.load_state_dict(ours.ff.net[3].state_dict())
    for i in (1, 2, 3):
        getattr(ref, f"norm{i}").load_state_dict(getattr(ours, f"norm{i}").state_dict())
    tgt, memory = torch.randn(2, 5, D), torch.randn(2, 3, D)
    torch.testing.assert_close(ours(tgt, memory), ref(tgt, memory), rtol=1e-5, atol=1e-5)


def test_positions_go_to_queries_and_keys_not_values():
    """DETR: q = k = x + pos, v = x. With value = x, the layer equals attention on explicit inputs."""
    torch.manual_seed(2)
    layer = EncoderLayer(D, H, FF, dropout=0.0).eval()
    x, pos = torch.randn(2, 4, D), torch.randn(4, D)
    attn = layer.self_attn(x + pos, x + pos, x, need_weights=False)[0]
    h = layer.norm1(x + attn)
    want = layer.norm2(h + layer.ff(h))
    torch.testing.assert_close(layer(x, pos), want)
    assert not torch.allclose(layer(x, pos), layer(x + pos))  # not the same as adding pos to the input


def test_full_decoder_stack_is_used():
    """Perturbing the LAST decoder layer changes the output (the original code's first-layer slip would not)."""
    torch.manual_seed(3)
    model = ACTTransformer(D, H, FF, n_encoder_layers=2, n_decoder_layers=3, n_queries=6, dropout=0.0).eval()
    src, pos = torch.randn(2, 3, D), torch.randn(3, D)
    before = model(src, pos)
    assert before.shape == (2, 6, D)
    with torch.no_grad():
        model.decoder.layers[-1].ff.net[3].bias.add_(torch.randn(D))  # not a constant: LayerNorm would remove it
    assert not torch.allclose(before, model(src, pos))


def test_sinusoidal_1d_closed_form():
    pe = sinusoidal_1d(11, 8)
    assert pe.shape == (11, 8)
    for p in (0, 3, 10):
        for i in range(4):
            assert math.isclose(pe[p, 2 * i].item(), math.sin(p / 10000 ** (2 * i / 8)), abs_tol=1e-6)
            assert math.isclose(pe[p, 2 * i + 1].item(), math.cos(p / 10000 ** (2 * i / 8)), abs_tol=1e-6)


def test_sinusoidal_2d_rows_and_columns():
    pe = sinusoidal_2d(3, 5, 16)
    assert pe.shape == (16, 3, 5)
    # first half depends on the row only, second half on the column only
    torch.testing.assert_close(pe[:8, :, 0:1].expand(8, 3, 5), pe[:8])
    torch.testing.assert_close(pe[8:, 0:1, :].expand(8, 3, 5), pe[8:])
    y = 2 * 2 * math.pi / 3  # row 1 -> position 2 of 3, scaled to (0, 2 pi]
    assert math.isclose(pe[0, 1, 0].item(), math.sin(y), abs_tol=1e-6)
    assert math.isclose(pe[1, 1, 0].item(), math.cos(y), abs_tol=1e-6)
    with pytest.raises(ValueError):
        sinusoidal_2d(3, 5, 6)
