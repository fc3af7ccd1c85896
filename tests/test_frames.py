"""Camera frames are checked at both ends: a data set's 'image' array (training) and an image observation (eval)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from coursekit.data.frames import frames_chw


def test_both_layouts_and_unit_floats_give_the_same_uint8_frames():
    rng = np.random.default_rng(0)
    hwc = rng.integers(0, 256, size=(4, 8, 6, 3), dtype=np.uint8)
    chw = hwc.transpose(0, 3, 1, 2)
    np.testing.assert_array_equal(frames_chw(hwc, (8, 6)), chw)
    np.testing.assert_array_equal(frames_chw(chw, (8, 6)), chw)
    np.testing.assert_array_equal(frames_chw(hwc.astype(np.float32) / 255.0, (8, 6)), chw)  # exact after rint
    assert frames_chw(hwc, (8, 6)).flags["C_CONTIGUOUS"]


@pytest.mark.parametrize("bad, words", [
    (np.zeros((4, 8, 6), np.uint8), r"\(N, H, W, 3\) or \(N, 3, H, W\).*got shape \(4, 8, 6\)"),
    (np.zeros((4, 8, 6, 4), np.uint8), r"got shape \(4, 8, 6, 4\)"),
    (np.zeros((4, 64, 64, 3), np.uint8), "64x64 frames.*expects 8x6"),
    (np.full((4, 8, 6, 3), 200.0, np.float32), r"float images must lie in \[0, 1\]; got values in \[200, 200\].*as uint8"),
    (np.full((4, 8, 6, 3), 7, np.int64), "uint8 0..255 or float in \\[0, 1\\]; got dtype int64"),
    (np.full((4, 8, 6, 3), np.nan, np.float32), "NaN or inf"),
])
def test_bad_frames_are_refused_with_what_came_and_what_is_expected(bad, words):
    with pytest.raises(ValueError, match=words):
        frames_chw(bad, (8, 6))


@settings(max_examples=60, deadline=None)
@given(shape=st.lists(st.integers(1, 5), min_size=1, max_size=5), dtype=st.sampled_from(["uint8", "float32", "int16"]),
       scale=st.sampled_from([1.0, 255.0, -1.0]))
def test_any_input_is_frames_or_one_clear_error(shape, dtype, scale):
    a = (np.ones(shape) * scale).astype(dtype)
    try:
        out = frames_chw(a, (2, 2))
    except ValueError as e:
        assert "images" in str(e)
        return
    assert out.dtype == np.uint8 and out.shape[1:] == (3, 2, 2)


def test_training_arrays_check_a_data_sets_image_frames():
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.data.features import training_arrays

    n = 6
    arrays = {"state": np.zeros((n, 5), np.float32), "action": np.zeros((n, 2), np.float32),
              "episode_index": np.zeros(n, np.int64), "image": np.full((n, 96, 96, 3), 128.0, np.float32)}
    ds = EpisodeDataset.from_episodes([{k: v for k, v in arrays.items() if k != "episode_index"}],
                                      {"env_id": "coursekit/PushT-v0", "obs_type": "image"})
    with pytest.raises(ValueError, match=r"the data set's 'image' frames must lie in \[0, 1\]; got values in \[128, 128\]"):
        training_arrays(ds, "pusht_image", image_size=(96, 96))
    with pytest.raises(ValueError, match="96x96 frames; this policy's encoder expects 48x48"):
        training_arrays(ds, "pusht_image", image_size=(48, 48))


def test_an_image_policy_refuses_0_255_floats_ints_and_channels_last():
    from coursekit.data import MinMaxNormalizer
    from coursekit.nn.unet1d import UNet1DConfig
    from coursekit.nn.vision import VisionEncoderConfig
    from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig

    vision = VisionEncoderConfig(image_size=(32, 32), crop_size=(28, 28), widths=(16, 16, 16, 16),
                                 blocks_per_stage=1, num_keypoints=8, feature_dim=16)
    policy = DiffusionPolicy(DiffusionPolicyConfig(obs_type="image", features="pusht_image", obs_dim=2, vision=vision,
                                                   unet=UNet1DConfig(down_dims=(16, 32), diffusion_step_embed_dim=16)))
    policy.set_normalizers({"agent_pos": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0)),
                            "action": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0))})
    pos = np.zeros((1, 2, 2), np.float32)
    ok = np.random.default_rng(0).uniform(0, 1, size=(1, 2, 3, 32, 32)).astype(np.float32)
    assert policy.predict_chunk({"image": ok, "agent_pos": pos}, num_inference_steps=1).shape == (1, 16, 2)
    with pytest.raises(ValueError, match=r"float observation 'image' must lie in \[0, 1\]; got values in \[.*\].*as uint8"):
        policy.predict_chunk({"image": ok * 255.0, "agent_pos": pos}, num_inference_steps=1)
    with pytest.raises(ValueError, match="observation 'image' must be uint8 0..255 or float in \\[0, 1\\]; got dtype int64"):
        policy.predict_chunk({"image": (ok * 255).astype(np.int64), "agent_pos": pos}, num_inference_steps=1)
    with pytest.raises(ValueError, match="channels last"):
        policy.predict_chunk({"image": torch.zeros(1, 2, 32, 32, 3, dtype=torch.uint8), "agent_pos": pos})


@pytest.mark.parametrize("values, words", [
    (np.full((2, 3), 255.0, np.float32), r"float x must lie in \[0, 1\]; got values in \[255, 255\]"),
    (np.full((2, 3), 3, np.int32), "x must be uint8 0..255 or float in \\[0, 1\\]; got dtype int32"),
    (np.array([0.5, np.inf], np.float32), "x contain NaN or inf"),
])
def test_numpy_frames_and_torch_frames_meet_one_check(values, words):
    from coursekit.data.frames import check_values

    for images in (values, torch.as_tensor(values)):  # the data set's frames, a policy's observation
        with pytest.raises(ValueError, match=words):
            check_values(images, "x")
    check_values(np.zeros((2, 3), np.uint8), "x")
    check_values(torch.rand(2, 3), "x")
