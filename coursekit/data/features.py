"""Policy input features computed from PushT states: what the network sees of the world.

The simulator never wraps the block angle (demonstrations show it from about -19 to +13 rad), so
a raw angle must never be min-max scaled: two identical poses would get different inputs and
the [-1, 1] range would be dominated by a few spinning episodes. Orientation is therefore
encoded as (sin, cos), which is continuous and identical for angle and angle + 2 pi.

Two feature sets, both pure numpy, vectorised over any leading shape:

    pusht_state      (..., 6)        [agent_x, agent_y, block_x, block_y, sin(angle), cos(angle)]
    pusht_keypoints  (..., 2 + 2K)   [agent_x, agent_y, kp0_x, kp0_y, ..., kp{K-1}_x, kp{K-1}_y]

The keypoint variant is the paper's "low-dim" PushT input (Chi et al. 2023, Sec. 5.1: agent
position plus 2-D keypoints of the T); here the keypoints are those of
``coursekit.envs.pusht_geometry.block_keypoints`` (their number K is whatever it returns).
Features are computed identically for demonstrations (angle unwrapped) and for environment
observations (angle mod 2 pi): both are functions of sin/cos of the angle only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

STATE_DIM = 5
"""A PushT state: [agent_x, agent_y, block_x, block_y, block_angle]."""

STATE_FEATURE_NAMES = ("agent_x", "agent_y", "block_x", "block_y", "sin_angle", "cos_angle")
"""The label of each dimension of :func:`pusht_state_features`."""


def _check_state(state: np.ndarray, who: str) -> np.ndarray:
    state = np.asarray(state, dtype=np.float64)
    if state.ndim < 1 or state.shape[-1] < STATE_DIM:
        raise ValueError(
            f"{who}: expected PushT states of shape (..., 5) = [agent_x, agent_y, block_x, block_y, angle] "
            f"(or the 7-d get_state() with velocities), got shape {state.shape}"
        )
    if not np.all(np.isfinite(state[..., :STATE_DIM])):
        raise ValueError(f"{who}: states contain NaN or inf (first bad row: {state[~np.isfinite(state).all(-1)][:1]})")
    return state[..., :STATE_DIM]


def pusht_state_features(state: np.ndarray) -> np.ndarray:
    """[ax, ay, bx, by, angle] (..., 5) -> [ax, ay, bx, by, sin angle, cos angle] (..., 6) float32."""
    state = _check_state(state, "pusht_state_features")
    angle = state[..., 4]
    out = np.concatenate([state[..., :4], np.sin(angle)[..., None], np.cos(angle)[..., None]], axis=-1)
    return out.astype(np.float32)  # (..., 6)


def _local_keypoints() -> np.ndarray:
    """(K, 2) keypoints of the T in its own frame (pose (0, 0, 0)), from the env's geometry."""
    from coursekit.envs.pusht_geometry import block_keypoints  # numpy/shapely only, no pymunk

    return np.asarray(block_keypoints((0.0, 0.0, 0.0)), dtype=np.float64)  # (K, 2)


def pusht_keypoint_features(state: np.ndarray) -> np.ndarray:
    """[ax, ay, bx, by, angle] (..., 5) -> [ax, ay, kp_x, kp_y for each of K keypoints] (..., 2 + 2K).

    The block pose maps a local point p to world ``(bx, by) + R(angle) p`` (pymunk's body
    transform), applied here to all states at once instead of one shapely call per state.
    """
    state = _check_state(state, "pusht_keypoint_features")
    local = _local_keypoints()  # (K, 2)
    c, s = np.cos(state[..., 4]), np.sin(state[..., 4])  # (...,)
    x = state[..., 2:3] + c[..., None] * local[:, 0] - s[..., None] * local[:, 1]  # (..., K)
    y = state[..., 3:4] + s[..., None] * local[:, 0] + c[..., None] * local[:, 1]  # (..., K)
    kps = np.stack([x, y], axis=-1).reshape(*state.shape[:-1], 2 * len(local))  # (..., 2K)
    return np.concatenate([state[..., :2], kps], axis=-1).astype(np.float32)  # (..., 2 + 2K)


FEATURES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "pusht_state": pusht_state_features,
    "pusht_keypoints": pusht_keypoint_features,
}
"""Feature name (stored in a policy's config) -> function from PushT states to features."""


def get_features(name: str) -> Callable[[np.ndarray], np.ndarray]:
    """The feature function called ``name`` (a key of :data:`FEATURES`)."""
    if name not in FEATURES:
        raise ValueError(f"unknown observation features {name!r}; expected one of {sorted(FEATURES)}")
    return FEATURES[name]


def feature_dim(name: str) -> int:
    """Do, the number of features ``name`` produces per step."""
    return int(get_features(name)(np.zeros(STATE_DIM)).shape[-1])
