"""PushT in LeRobot's conventions and back: keypoint order, coordinates, block angle, rewards.

LeRobot's PushT sets (``lerobot/pusht``, ``lerobot/pusht_keypoints``, converted from the Diffusion
Policy data with the gym-pusht env) describe a frame as::

    observation.state               (2,)  agent [x, y]
    observation.environment_state   (16,) the T's 8 corners [x0, y0, ..., x7, y7] (pusht_keypoints)
    observation.image               (96, 96, 3) camera frame (pusht)
    action                          (2,)  pusher target [x, y]
    next.reward / next.success      reward clip(coverage / 0.95, 0, 1) and coverage > 0.95 of the NEXT state

Coordinates: the same 512 x 512 world as coursekit's PushT (y down, same origin and units), so
positions map one to one. A coursekit state is [agent_x, agent_y, block_x, block_y, angle]; LeRobot
keeps no block pose, only the corners, which are the pose applied to the T's local corners.

Keypoint order. gym-pusht lists each of the T's two boxes as pymunk returns its vertices
(counter-clockwise in pymunk's y-up maths, starting from the lowest-x of the lowest-y corners), so
in the T's own frame (crossbar top edge on y = 0, stem down to y = 120)::

    LeRobot  k:  0         1        2        3         4         5        6         7
    local (x,y): (-60, 0)  (60, 0)  (60, 30) (-60, 30) (-15, 30) (15, 30) (15, 120) (-15, 120)
    coursekit:   3         2        1        0         4         5        6         7

coursekit's ``pusht_keypoints`` features (``coursekit.envs.pusht_geometry.KEYPOINTS_LOCAL``) list
the crossbar from its lower-left corner instead, so LeRobot's k = coursekit's
:data:`FROM_COURSEKIT` [k]; the stem corners agree. tests/test_lerobot_pusht.py checks this order
against pymunk itself and against a frame of ``lerobot/pusht_keypoints``.

Block angle. The corners fix the pose up to nothing: :func:`pose_from_keypoints` fits the rigid
transform (least squares, exact for exact corners) and returns the angle in (-pi, pi], which
:func:`states_from_lerobot` unwraps along each episode, as coursekit's demonstrations keep it
(features only use sin/cos of it, so any 2 pi offset is the same pose).

Rewards: LeRobot's frame t carries the reward of the state after action t; for the last frame of
an episode, whose next state is not recorded, the last state's reward is repeated (as LeRobot's
own conversion does). ``next.done`` is True on each episode's last frame only.
"""

from __future__ import annotations

import numpy as np

from coursekit.envs import pusht_geometry as geo

LEROBOT_KEYPOINTS_LOCAL = np.array([(-60, 0), (60, 0), (60, 30), (-60, 30),
                                    (-15, 30), (15, 30), (15, 120), (-15, 120)], dtype=np.float64)
"""(8, 2) the T's corners in gym-pusht's order (LeRobot's observation.environment_state), local frame."""


def _match_order() -> np.ndarray:
    mine = np.asarray(geo.KEYPOINTS_LOCAL, dtype=np.float64)  # (8, 2)
    order = [int(np.flatnonzero(np.all(mine == p, axis=1))[0]) for p in LEROBOT_KEYPOINTS_LOCAL]
    if sorted(order) != list(range(len(mine))):
        raise RuntimeError("the gym-pusht corners are not a reordering of coursekit's keypoints")
    return np.array(order)


FROM_COURSEKIT = _match_order()
"""(8,) coursekit keypoint index of each LeRobot keypoint: [3, 2, 1, 0, 4, 5, 6, 7]."""

KEYPOINT_NAMES = tuple(f"k{k}_{c}" for k in range(len(LEROBOT_KEYPOINTS_LOCAL)) for c in "xy")
"""Labels of observation.environment_state's 16 dimensions."""


def lerobot_keypoints(states: np.ndarray) -> np.ndarray:
    """PushT states (N, 5) -> LeRobot's observation.environment_state (N, 16) float64, gym-pusht order.

    Each state's block pose maps the local corners to the world with the env's own transform
    (``pusht_geometry.local_to_world``, pymunk's body transform).
    """
    states = np.asarray(states, dtype=np.float64)
    corners = [geo.local_to_world(LEROBOT_KEYPOINTS_LOCAL, s[2:5]) for s in states]  # N x (8, 2)
    return np.asarray(corners, dtype=np.float64).reshape(len(states), -1)  # (N, 16)


def pose_from_keypoints(keypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LeRobot corners (N, 16) -> block poses (N, 3) [x, y, angle in (-pi, pi]] and the fit's RMS error (N,) px.

    2-D Procrustes without scaling: the angle maximises sum_k <R(angle) p_k, q_k - q_mean> over the
    local corners p_k (centred) and world corners q_k; the position is q_mean - R p_mean.
    """
    world = np.asarray(keypoints, dtype=np.float64).reshape(len(keypoints), -1, 2)  # (N, 8, 2)
    local = LEROBOT_KEYPOINTS_LOCAL  # (8, 2)
    p = local - local.mean(axis=0)  # (8, 2)
    q = world - world.mean(axis=1, keepdims=True)  # (N, 8, 2)
    cos_part = np.einsum("kd,nkd->n", p, q)  # sum p.q
    sin_part = np.einsum("k,nk->n", p[:, 0], q[..., 1]) - np.einsum("k,nk->n", p[:, 1], q[..., 0])  # sum p x q
    angle = np.arctan2(sin_part, cos_part)  # (N,)
    c, s = np.cos(angle), np.sin(angle)
    rotated = np.stack([c[:, None] * local[:, 0] - s[:, None] * local[:, 1],
                        s[:, None] * local[:, 0] + c[:, None] * local[:, 1]], axis=-1)  # (N, 8, 2)
    origin = world.mean(axis=1) - rotated.mean(axis=1)  # (N, 2)
    error = np.sqrt(((rotated + origin[:, None] - world) ** 2).sum(-1).mean(-1))  # (N,)
    return np.concatenate([origin, angle[:, None]], axis=1), error


def states_from_lerobot(agent: np.ndarray, keypoints: np.ndarray, episode_ends: np.ndarray,
                        tolerance_px: float = 0.5) -> np.ndarray:
    """agent (N, 2) + corners (N, 16) -> coursekit states (N, 5), the angle unwrapped within each episode.

    Raises ValueError if the corners are not the T in gym-pusht's order (fit error above ``tolerance_px``).
    """
    poses, error = pose_from_keypoints(keypoints)
    if np.any(~(error <= tolerance_px)):
        bad = int(np.flatnonzero(~(error <= tolerance_px))[0])
        raise ValueError(f"observation.environment_state of frame {bad} is not the T's 8 corners in gym-pusht's order "
                         f"(a rigid T fits them only to {error[bad]:.3g} px RMS, tolerance {tolerance_px} px)")
    starts = np.concatenate([[0], episode_ends[:-1]])
    for a, b in zip(starts, episode_ends, strict=True):
        poses[a:b, 2] = np.unwrap(poses[a:b, 2])
    return np.concatenate([np.asarray(agent, dtype=np.float64), poses], axis=1)  # (N, 5)


def next_rewards(states: np.ndarray, episode_ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 5) states -> next.reward (N,) float32 and next.success (N,) bool, per the module docstring."""
    scorer = geo.CoverageScorer()
    coverage = np.array([scorer(tuple(s[2:5])) for s in np.asarray(states, dtype=np.float64)])  # (N,)
    following = np.arange(len(coverage)) + 1  # (N,) the frame whose state follows action t
    following[np.asarray(episode_ends) - 1] -= 1  # an episode's last frame repeats its own state
    nxt = coverage[following]
    reward = np.clip(nxt / geo.SUCCESS_THRESHOLD, 0.0, 1.0).astype(np.float32)
    return reward, nxt > geo.SUCCESS_THRESHOLD
