"""PushT policy features: (sin, cos) of the unwrapped angle, keypoints against the env's own geometry."""

from __future__ import annotations

import numpy as np
import pytest

from coursekit.data.features import (FEATURES, feature_dim, get_features, pusht_keypoint_features,
                                     pusht_state_features)
from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht import PushTEnv


def test_state_features_closed_form():
    s = np.array([[10.0, 20.0, 30.0, 40.0, 0.3], [1.0, 2.0, 3.0, 4.0, -7.0]])
    f = pusht_state_features(s)
    assert f.shape == (2, 6) and f.dtype == np.float32
    np.testing.assert_allclose(f[:, :4], s[:, :4])
    np.testing.assert_allclose(f[:, 4], np.sin(s[:, 4]), rtol=1e-6)
    np.testing.assert_allclose(f[:, 5], np.cos(s[:, 4]), rtol=1e-6)


@pytest.mark.parametrize("fn", [pusht_state_features, pusht_keypoint_features])
def test_unwrapped_and_wrapped_angles_give_the_same_features(fn):
    rng = np.random.default_rng(0)
    s = np.column_stack([rng.uniform(0, 512, (50, 4)), rng.uniform(-20, 20, 50)])
    wrapped = s.copy()
    wrapped[:, 4] = np.mod(s[:, 4], 2 * np.pi)  # what the env's "state" observation reports
    np.testing.assert_allclose(fn(s), fn(wrapped), atol=1e-3)


def test_keypoint_features_match_env_observation_and_geometry():
    env = PushTEnv(obs_type="keypoints")
    obs, _ = env.reset(seed=3)
    for _ in range(5):
        obs, *_ = env.step([300.0, 300.0])
    state = env.get_state()
    np.testing.assert_allclose(pusht_keypoint_features(state), obs, atol=1e-3)  # float32 features
    pose = state[2:5]
    np.testing.assert_allclose(pusht_keypoint_features(state)[2:].reshape(-1, 2), geo.block_keypoints(pose), atol=1e-3)
    batch = np.stack([state, state + np.array([5, -5, 10, 0, 1.0, 0, 0])])[None]  # (1, 2, 7)
    assert pusht_keypoint_features(batch).shape == (1, 2, 18) == (1, 2, feature_dim("pusht_keypoints"))


def test_registry_and_bad_input():
    assert set(FEATURES) == {"pusht_state", "pusht_keypoints", "pusht_image", "aloha_state", "aloha_qpos", "aloha_image",
                             "raw_state"}
    raw = get_features("raw_state")
    assert raw.task is None  # fits every task
    np.testing.assert_array_equal(raw(np.array([[0.5, -1.25]])), np.array([[0.5, -1.25]], dtype=np.float32))
    with pytest.raises(ValueError, match="finite observation vectors"):
        raw(np.array([np.inf]))
    assert feature_dim("pusht_state") == 6 and feature_dim("aloha_qpos") == 14
    with pytest.raises(ValueError, match="unknown observation features"):
        get_features("pusht_pixels")
    with pytest.raises(ValueError, match="shape"):
        pusht_state_features(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="NaN"):
        pusht_state_features(np.array([[1.0, 2.0, np.nan, 4.0, 5.0]]))
