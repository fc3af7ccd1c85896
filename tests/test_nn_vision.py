"""The GroupNorm ResNet image encoder, spatial softmax and crops."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from coursekit.nn import SpatialSoftmax, VisionEncoder, VisionEncoderConfig, center_crop, random_crop, spatial_softmax

TINY = VisionEncoderConfig(widths=(16, 16, 32, 32), blocks_per_stage=1, num_keypoints=8, feature_dim=24)


def test_shapes_in_train_and_eval_and_no_batchnorm():
    torch.manual_seed(0)
    enc = VisionEncoder(TINY)
    x = torch.rand(2, 3, 96, 96) * 2 - 1
    assert enc.train()(x, generator=torch.Generator().manual_seed(0)).shape == (2, 24)
    assert enc.eval()(x).shape == (2, 24)
    for cfg in (TINY, VisionEncoderConfig.preset("resnet18")):
        mods = list(VisionEncoder(cfg).modules())
        assert not any(isinstance(m, nn.modules.batchnorm._BatchNorm) for m in mods)
        assert any(isinstance(m, nn.GroupNorm) for m in mods)


def test_resnet18_preset_size():
    n = sum(p.numel() for p in VisionEncoder(VisionEncoderConfig.preset("resnet18")).parameters())
    assert 11.0e6 < n < 11.5e6  # ResNet-18's conv trunk is 11.2 M parameters


def test_eval_is_deterministic_train_crop_is_seeded():
    enc = VisionEncoder(TINY)
    x = torch.rand(3, 3, 96, 96)
    enc.eval()
    torch.testing.assert_close(enc(x), enc(x))
    enc.train()
    a = enc(x, generator=torch.Generator().manual_seed(5))
    torch.testing.assert_close(a, enc(x, generator=torch.Generator().manual_seed(5)))


def test_without_random_crops_training_sees_the_centre_crop():
    import dataclasses

    torch.manual_seed(0)
    enc = VisionEncoder(dataclasses.replace(TINY, random_crops=False))
    x = torch.rand(3, 3, 96, 96) * 2 - 1
    train = enc.train()(x, generator=torch.Generator().manual_seed(5))
    torch.testing.assert_close(train, enc.eval()(x))  # GroupNorm: no train/eval difference but the crop
    augmented = VisionEncoder(TINY)
    augmented.load_state_dict(enc.state_dict())
    assert not torch.allclose(augmented.train()(x, generator=torch.Generator().manual_seed(5)), train)
    with pytest.raises(ValueError, match="random_crops must be True or False, got 'no'"):
        VisionEncoderConfig(random_crops="no")


def test_crops_against_slicing():
    x = torch.arange(2 * 1 * 6 * 6, dtype=torch.float32).reshape(2, 1, 6, 6)
    torch.testing.assert_close(center_crop(x, 4), x[..., 1:5, 1:5])
    g = torch.Generator().manual_seed(0)
    out = random_crop(x, (4, 3), generator=g)
    g = torch.Generator().manual_seed(0)
    top, left = torch.randint(0, 3, (2,), generator=g), torch.randint(0, 4, (2,), generator=g)
    for i in range(2):
        torch.testing.assert_close(out[i], x[i, :, top[i]:top[i] + 4, left[i]:left[i] + 3])


def test_spatial_softmax_finds_the_peak():
    ss = SpatialSoftmax(1, 1)
    with torch.no_grad():
        ss.to_maps.weight.fill_(1.0)
        ss.to_maps.bias.zero_()
    fmap = torch.zeros(1, 1, 5, 9)
    fmap[0, 0, 4, 0] = 100.0  # bottom-left corner: x = -1, y = +1
    torch.testing.assert_close(ss(fmap), torch.tensor([[[-1.0, 1.0]]]), atol=1e-4, rtol=0)


def test_spatial_softmax_closed_forms_and_the_layer_uses_it():
    maps = torch.zeros(1, 3, 4, 6, dtype=torch.float64)
    maps[0, 0, 0, 5] = 1e3  # top-right pixel centre: x = +1, y = -1
    maps[0, 1, 3, 1] = maps[0, 1, 3, 3] = 1e3  # two equal peaks on the last row: their midpoint
    want = torch.tensor([[[1.0, -1.0], [-1 + 2 * 2 / 5, 1.0], [0.0, 0.0]]], dtype=torch.float64)  # map 2 is flat
    torch.testing.assert_close(spatial_softmax(maps), want, rtol=0, atol=1e-12)
    calls = []
    layer = SpatialSoftmax(2, 3, keypoints_fn=lambda m: calls.append(m.shape) or spatial_softmax(m))
    x = torch.randn(2, 2, 5, 7)
    torch.testing.assert_close(layer(x), spatial_softmax(layer.to_maps(x)))
    assert calls == [(2, 3, 5, 7)]
    enc = VisionEncoder(TINY, keypoints_fn=lambda m: torch.zeros(m.shape[0], m.shape[1], 2))
    assert enc.pool.keypoints_fn is not None and enc.eval()(torch.rand(1, 3, 96, 96)).shape == (1, 24)


@pytest.mark.parametrize("bad, words", [(torch.rand(3, 4, 5), r"\(B, K, H, W\), got \(3, 4, 5\) torch.float32"),
                                        (torch.ones(1, 2, 3, 4, dtype=torch.long), "float tensor.*torch.int64"),
                                        ([[1.0]], "got list")])
def test_spatial_softmax_refuses_bad_maps(bad, words):
    with pytest.raises(ValueError, match=words):
        spatial_softmax(bad)


def test_bad_input_raises():
    with pytest.raises(ValueError, match=r"got \(2, 3, 64, 64\)"):
        VisionEncoder(TINY)(torch.rand(2, 3, 64, 64))
    with pytest.raises(ValueError, match="crop_size"):
        VisionEncoderConfig(crop_size=(100, 100))
    with pytest.raises(ValueError, match="group_size"):
        VisionEncoderConfig(widths=(24, 32))


def test_keypoints_in_frame_maps_the_last_map_back_to_frame_pixels():
    """keypoints_in_frame: [-1, 1] over the last map's cell centres -> crop -> resize -> frame pixels (closed form)."""
    fixed = torch.tensor([[-1.0, -1.0], [0.0, 0.0], [1.0, 1.0]])  # (K, 2): first cell, centre, last cell

    def keypoints_fn(maps):  # (B, K, H, W) -> (B, K, 2), whatever the maps hold
        return fixed.expand(maps.shape[0], -1, -1) + 0 * maps.mean((2, 3))[..., None]

    cfg = VisionEncoderConfig.preset("small")  # 96x96 frames, encoded at 48x48, 42x42 centre crop
    cfg = VisionEncoderConfig(**{**cfg.__dict__, "num_keypoints": 3})
    enc = VisionEncoder(cfg, keypoints_fn=keypoints_fn)
    w = enc.stages(enc.stem(torch.zeros(1, 3, 42, 42))).shape[-1]  # the last map's width (2 here)
    got = enc.keypoints_in_frame(torch.zeros(2, 3, 96, 96))  # (2, 3, 2)
    assert got.shape == (2, 3, 2) and enc.training  # the mode is restored
    off, scale, cell = (48 - 42) // 2, 96 / 48, 42 / w
    np.testing.assert_allclose(got[0, 1].numpy(), [48.0, 48.0], atol=1e-5)  # the centre of a centred crop
    np.testing.assert_allclose(got[0, 0].numpy(), [(0.5 * cell + off) * scale] * 2, atol=1e-5)
    np.testing.assert_allclose(got[0, 2].numpy(), [((w - 0.5) * cell + off) * scale] * 2, atol=1e-5)
