"""Stage 1 of the pixel route: the encoder learns to read a position from frames; frame resizing."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coursekit.nn.vision import VisionEncoder, VisionEncoderConfig
from coursekit.nn.vision_pretrain import PretrainConfig, freeze, predict_targets, pretrain_encoder

SMALL = VisionEncoderConfig(widths=(16, 32), blocks_per_stage=1, image_size=32, crop_size=28, frame_size=64,
                            num_keypoints=8, feature_dim=16)


def squares(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3, 64, 64) uint8 frames with one bright 8x8 square each, and its centre (n, 2) in pixels."""
    rng = np.random.default_rng(seed)
    corner = rng.integers(8, 48, size=(n, 2))  # inside the centre crop after resizing
    frames = np.zeros((n, 3, 64, 64), np.uint8)
    for i, (r, c) in enumerate(corner):
        frames[i, :, r:r + 8, c:c + 8] = 255
    return frames, (corner + 4).astype(np.float32)


def test_the_encoder_learns_where_the_square_is():
    frames, centres = squares(512, 0)
    enc = VisionEncoder(SMALL)
    out = pretrain_encoder(enc, frames, centres, PretrainConfig(steps=150, batch_size=32, lr=3e-3))
    test_frames, test_centres = squares(128, 1)
    err = np.abs(predict_targets(enc, out["readout"], out["mean"], out["std"], test_frames) - test_centres).mean()
    spread = np.abs(test_centres - centres.mean(0)).mean()  # the error of always guessing the mean
    assert np.mean(out["loss"][-20:]) < 0.2 * np.mean(out["loss"][:20])
    assert err < 0.25 * spread, f"mean error {err:.2f} px against {spread:.2f} px for the mean guess"


def test_same_seed_same_losses_and_freeze_stops_gradients():
    frames, centres = squares(64, 0)
    runs = [pretrain_encoder(VisionEncoder(SMALL), frames, centres, PretrainConfig(steps=3, batch_size=8))["loss"]
            for _ in range(2)]
    assert runs[0] == runs[1]
    enc = freeze(VisionEncoder(SMALL))
    assert not any(p.requires_grad for p in enc.parameters())
    assert not enc(torch.rand(2, 3, 64, 64) * 2 - 1).requires_grad  # no graph through a frozen encoder


def test_frames_are_area_resized_to_the_working_size():
    enc = VisionEncoder(SMALL).eval()
    frames = torch.rand(2, 3, 64, 64) * 2 - 1
    pooled = frames.reshape(2, 3, 32, 2, 32, 2).mean((3, 5))  # (2, 3, 32, 32): the mean of each 2x2 block
    direct = VisionEncoder(VisionEncoderConfig(**{**SMALL.__dict__, "frame_size": None})).eval()
    direct.load_state_dict(enc.state_dict())
    assert torch.allclose(enc(frames), direct(pooled), atol=1e-6)
    with pytest.raises(ValueError, match=r"must fit in frame_size"):
        VisionEncoderConfig(image_size=96, frame_size=48)


@pytest.mark.parametrize("bad, match", [
    (np.zeros((4, 3, 32, 32), np.uint8), r"images must be \(N, 3, 64, 64\) uint8 frames, got \(4, 3, 32, 32\)"),
    (np.zeros((4, 3, 64, 64), np.float32), r"uint8 frames, got \(4, 3, 64, 64\) float32"),
])
def test_bad_frames_are_refused_with_the_expected_shape(bad, match):
    with pytest.raises(ValueError, match=match):
        pretrain_encoder(VisionEncoder(SMALL), bad, np.zeros((4, 2), np.float32))


def test_nan_targets_are_refused():
    frames, centres = squares(4, 0)
    centres[1, 0] = np.nan
    with pytest.raises(ValueError, match="targets must be finite"):
        pretrain_encoder(VisionEncoder(SMALL), frames, centres)


def test_the_small_preset_takes_96x96_frames_and_works_at_48x48():
    cfg = VisionEncoderConfig.preset("small")
    assert (cfg.input_size, cfg.image_size, cfg.crop_size) == ((96, 96), (48, 48), (42, 42))
    assert VisionEncoder(cfg).eval()(torch.zeros(2, 3, 96, 96)).shape == (2, cfg.feature_dim)
