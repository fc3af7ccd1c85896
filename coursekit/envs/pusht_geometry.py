"""PushT geometry: the T block, the goal pose and the coverage score (pure numpy + shapely).

No physics here (no pymunk), so plotting, planners and tests can use the geometry on its own.

Conventions (those of the reference environment: Chi et al. 2023's ``pusht_env.py`` and gym-pusht):

- The world is 512 x 512 units (= pixels of the reference renderer), x to the right, y DOWN
  (image convention). A pose is ``(x, y, angle)``: the world position of the block's BODY
  ORIGIN (the middle of the crossbar's top edge, not the centre of gravity) and its rotation
  in radians. ``local_to_world`` rotates by ``angle`` with the usual matrix
  [[cos, -sin], [sin, cos]], as pymunk does; with y down this looks clockwise on screen. It is
  the ONE body-to-world transform of the library (env, expert, features), vectorised over poses.
- The T (scale 30) is two boxes on one body, in body-local coordinates::

        (-60,0) +--------------------+ (60,0)       crossbar 120 x 30
                |                    |
        (-60,30)+------+      +------+ (60,30)
                       |      |                     stem 30 x 90
                       |      |
               (-15,120)+------+ (15,120)
"""

from __future__ import annotations

import math

import numpy as np
import shapely

# --------------------------------------------------------------------------------------------
# Constants (immutable: tuples and read-only arrays)
# --------------------------------------------------------------------------------------------
WORLD_SIZE = 512.0
"""Side of the square world, in units (= reference render pixels)."""

T_SCALE = 30.0
"""Width of the T's bars; the crossbar is 4 x T_SCALE long, the whole T 4 x T_SCALE tall."""

AGENT_RADIUS = 15.0
"""Radius of the round pusher (the "agent")."""

T_MASS = 1.0
"""Mass of the T block."""

# The reference computes the moment as moment_for_poly(mass, crossbar) + moment_for_poly(mass,
# crossbar): a copy-paste slip that uses the crossbar twice (1500 + 1500, both about the body
# origin). With the stem's vertices it would be 1500 + 6375 = 7875. We KEEP 3000 on purpose so
# that the dynamics, and hence published PushT scores and reference data, stay comparable.
T_MOMENT = 3000.0
"""Moment of inertia of the T block (the reference's value, see the comment above)."""

# The reference sets the centre of gravity to the MEAN of the two boxes' centroids,
# ((0, 15) + (0, 75)) / 2 = (0, 45); the area-weighted centroid would be (0, 40.7). Kept.
T_COG_LOCAL = (0.0, 45.0)
"""Centre of gravity of the T in body-local coordinates (the reference's value)."""

GOAL_POSE = (256.0, 256.0, math.pi / 4)
"""Target pose (x, y, angle) of the T."""

SUCCESS_THRESHOLD = 0.95
"""Coverage above which an episode counts as a success (and terminates)."""

WALL_LO, WALL_HI, WALL_RADIUS = 5.0, 506.0, 2.0
"""The four static walls run between (WALL_LO, WALL_LO) and (WALL_HI, WALL_HI), radius 2."""


def _frozen(a: list[tuple[float, float]]) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.flags.writeable = False
    return arr


CROSSBAR_LOCAL = _frozen([(-60, 30), (60, 30), (60, 0), (-60, 0)])
"""(4, 2) crossbar corners in body-local coordinates (reference vertex order)."""

STEM_LOCAL = _frozen([(-15, 30), (15, 30), (15, 120), (-15, 120)])
"""(4, 2) stem corners in body-local coordinates."""

T_OUTLINE_LOCAL = _frozen([(-60, 0), (60, 0), (60, 30), (15, 30),
                           (15, 120), (-15, 120), (-15, 30), (-60, 30)])
"""(8, 2) outline of the whole T as ONE simple polygon (for coverage and drawing)."""

KEYPOINTS_LOCAL = np.concatenate([CROSSBAR_LOCAL, STEM_LOCAL])
KEYPOINTS_LOCAL.flags.writeable = False
"""(8, 2) keypoints: the 4 crossbar corners then the 4 stem corners, in the order above.
(The gym-pusht package exposes the same 8 polygon corners; the paper used 9 keypoints.)"""

T_AREA = 6300.0
"""Area of the T: 120 * 30 + 30 * 90."""


# --------------------------------------------------------------------------------------------
# Poses
# --------------------------------------------------------------------------------------------
def _check_pose(pose) -> tuple[float, float, float]:
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (3,):
        raise ValueError(f"pose must have shape (3,) = (x, y, angle), got shape {p.shape}: {pose!r}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"pose must be finite, got {pose!r}")
    return float(p[0]), float(p[1]), float(p[2])


def as_state5(state) -> np.ndarray:
    """The first five entries [ax, ay, bx, by, angle] of a PushT state as float64, validated.

    Accepts the 5-d observation or the env's longer 7-d state (extra entries are ignored).
    """
    s = np.asarray(state, dtype=np.float64)
    if s.ndim != 1 or s.shape[0] < 5:
        raise ValueError(f"state must be (5,) [ax, ay, bx, by, angle] (extra entries ignored), got shape {s.shape}")
    if not np.all(np.isfinite(s[:5])):
        raise ValueError(f"state must be finite, got {s[:5].tolist()!r}")
    return s[:5]


def _check_poses(pose) -> np.ndarray:
    p = np.asarray(pose, dtype=np.float64)
    if p.ndim == 0 or p.shape[-1] != 3:
        raise ValueError(f"pose must have shape (..., 3) = (x, y, angle), got shape {p.shape}: {pose!r}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"pose must be finite, got {pose!r}")
    return p


def local_to_world(points: np.ndarray, pose) -> np.ndarray:
    """Body-local points (..., 2) -> world (..., 2) for poses (..., 3) = (x, y, angle), broadcasting.

    ``world = (x, y) + R(angle) p`` (pymunk's body transform). One pose (3,) maps every point;
    poses (B, 1, 3) and points (K, 2) give (B, K, 2).
    """
    pose = _check_poses(pose)
    p = np.asarray(points, dtype=np.float64)
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])  # (...,)
    return np.stack([p[..., 0] * c - p[..., 1] * s + pose[..., 0],
                     p[..., 0] * s + p[..., 1] * c + pose[..., 1]], axis=-1)  # (..., 2)


def world_to_local(points: np.ndarray, pose) -> np.ndarray:
    """World points (..., 2) -> body-local (..., 2) for poses (..., 3), broadcasting: the inverse of
    :func:`local_to_world`, ``R(-angle) (point - (x, y))``."""
    pose = _check_poses(pose)
    d = np.asarray(points, dtype=np.float64) - pose[..., :2]  # (..., 2)
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])  # (...,)
    return np.stack([d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c], axis=-1)  # (..., 2)


def block_polygons(pose) -> list[np.ndarray]:
    """The T's two boxes in world coordinates: ``[crossbar (4, 2), stem (4, 2)]``."""
    return [local_to_world(CROSSBAR_LOCAL, pose), local_to_world(STEM_LOCAL, pose)]


def block_outline(pose) -> np.ndarray:
    """The T's outline (8, 2) in world coordinates (one simple, non-convex polygon)."""
    return local_to_world(T_OUTLINE_LOCAL, pose)


def block_keypoints(pose) -> np.ndarray:
    """The 8 keypoints (8, 2) in world coordinates: crossbar corners, then stem corners
    (order of ``KEYPOINTS_LOCAL``)."""
    return local_to_world(KEYPOINTS_LOCAL, pose)


def cog_world(pose) -> np.ndarray:
    """World position (2,) of the block's centre of gravity for ``pose``."""
    return local_to_world(np.array([T_COG_LOCAL]), pose)[0]


def swept_angle(points: np.ndarray, pose) -> float:
    """Signed angle (rad) a path ``points`` (K >= 2, 2) (world px) turns about the centre of gravity
    of the T at ``pose`` (x, y, angle): the sum of the angles between successive radius vectors.
    > 0 is clockwise on screen (y points down), the expert's "cw"."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[-1] != 2 or len(p) < 2:
        raise ValueError(f"points must be (K >= 2, 2) world coordinates, got shape {np.shape(points)}")
    r = p - cog_world(pose)  # (K, 2)
    u, v = r[:-1], r[1:]
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]  # y down: cross > 0 turns clockwise on screen
    return float(np.arctan2(cross, (u * v).sum(-1)).sum())


def legacy_pose(position, angle: float) -> tuple[float, float, float]:
    """Pose reached by the reference's LEGACY reset order on a body at angle 0.

    The reference sets ``body.position`` first (with the body still at angle 0) and THEN
    ``body.angle``; pymunk rotates a body about its centre of gravity c = T_COG_LOCAL, so the
    body origin ends at ``position + c - R(angle) c`` instead of at ``position``.
    """
    x, y, a = _check_pose((position[0], position[1], angle))
    cx, cy = T_COG_LOCAL
    c, s = math.cos(a), math.sin(a)
    return (x + cx - (c * cx - s * cy), y + cy - (s * cx + c * cy), a)


# --------------------------------------------------------------------------------------------
# Coverage (the reward's basis)
# --------------------------------------------------------------------------------------------
def t_shape(pose) -> shapely.Polygon:
    """The T at ``pose`` as a shapely polygon."""
    return shapely.Polygon(block_outline(pose))


class CoverageScorer:
    """Coverage against one fixed goal pose, with the goal polygon built (and prepared) once.

    coverage = area(goal_T intersect block_T) / area(goal_T), as in the reference.
    """

    def __init__(self, goal_pose=GOAL_POSE):
        self.goal_pose = _check_pose(goal_pose)
        self._goal = t_shape(self.goal_pose)
        shapely.prepare(self._goal)
        self._goal_area = float(self._goal.area)

    def __call__(self, pose) -> float:
        inter = shapely.intersection(self._goal, t_shape(pose))
        return float(shapely.area(inter)) / self._goal_area


def coverage(pose, goal_pose=GOAL_POSE) -> float:
    """Fraction of the goal T covered by the block T at ``pose`` (in [0, 1])."""
    return CoverageScorer(goal_pose)(pose)


def reward_from_coverage(cov: float) -> float:
    """The reference reward: clip(coverage / 0.95, 0, 1)."""
    return float(min(max(cov / SUCCESS_THRESHOLD, 0.0), 1.0))
