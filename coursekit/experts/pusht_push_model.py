"""Where can the pusher push the T, and where will the T go? A quasi-static push model.

PushT's physics makes pushing predictable (the semantics in ``coursekit/envs/pusht.py``):

- ``space.damping = 0`` zeroes the block's velocity every substep: the T moves only while it
  is pressed, and stops the moment the pusher stops (quasi-static pushing).
- Contacts are frictionless, so the pusher can only push along the contact normal: the inward
  normal of the edge it touches, or, at a convex corner, any direction within that corner's
  90 degree range (the round pusher touches the corner point itself).

Pushing the pusher a distance d into the block at a contact with lever arm
k = (contact - centre of gravity) x normal gives an impulse P along the normal that keeps the
contact point moving with the pusher:  P (1/m + k^2/I) = d.  So the centre of gravity moves
J = P/m = d / (1 + m k^2 / I) along the normal and the block turns by P k / I.
(I = 3000 is the reference's moment of inertia, a known slip kept for comparability.)

This module holds the candidate contacts (computed once, in the T's own frame), the pose error
that ranks them, and the model's prediction for a batch of (contact, depth) pushes. The model
keeps the contact fixed on the body, so it is a screening tool: the planner checks the best
few candidates in a scratch copy of the simulator before pushing for real.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coursekit.envs import pusht_geometry as geo
from coursekit.experts.pusht_clearance import point_distance

_COG = np.asarray(geo.T_COG_LOCAL, dtype=np.float64)  # (2,) centre of gravity, body frame


# --------------------------------------------------------------------------------------------
# Pose error: how far the T is from the goal (what every push tries to shrink)
# --------------------------------------------------------------------------------------------
def keypoints(poses: np.ndarray) -> np.ndarray:
    """The T's 8 corners (..., 8, 2) in world coordinates for poses (..., 3) = (x, y, angle)."""
    poses = np.asarray(poses, dtype=np.float64)
    return geo.local_to_world(geo.KEYPOINTS_LOCAL, poses[..., None, :])  # (..., 8, 2)


def pose_error(poses: np.ndarray, goal_pose=geo.GOAL_POSE) -> np.ndarray:
    """RMS distance (...,) of the T's 8 corners from their places in the goal pose.

    One number in pixels for position and orientation together; it is periodic in the angle
    (the simulator never wraps it) and zero only at the goal.
    """
    diff = keypoints(poses) - keypoints(np.asarray(goal_pose, dtype=np.float64))  # (..., 8, 2)
    return np.sqrt((diff**2).sum(-1).mean(-1))


# --------------------------------------------------------------------------------------------
# Candidate contacts on the T (body frame, computed once)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Contacts:
    """Candidate pushes' contacts in the T's body frame (M of them).

    point: (M, 2) where the pusher touches the T's boundary.
    normal: (M, 2) unit push direction (pointing INTO the block).
    lever: (M,) k = (point - cog) x normal, the push's lever arm about the centre of gravity.
    corner: (M,) bool, True for a push on a convex corner (direction inside its 90 degree range).
    """

    point: np.ndarray
    normal: np.ndarray
    lever: np.ndarray
    corner: np.ndarray

    def __len__(self) -> int:
        return len(self.point)

    def standoff(self, gap: float, radius: float = geo.AGENT_RADIUS) -> np.ndarray:
        """(M, 2) pusher centres (body frame) a ``gap`` away from touching each contact."""
        return self.point - self.normal * (radius + gap)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def outline_corners() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The T's outline as (8, 2) vertices, (8, 2) inward unit normals of edge i -> i+1, and
    (8,) bool "vertex i is convex" (6 convex corners, 2 inside corners under the crossbar)."""
    v = np.asarray(geo.T_OUTLINE_LOCAL, dtype=np.float64)  # (8, 2)
    edge = np.roll(v, -1, axis=0) - v  # (8, 2) edge i runs from v[i] to v[i+1]
    orientation = np.sign(_cross(v, np.roll(v, -1, axis=0)).sum())  # +1: interior on the left
    inward = orientation * np.stack([-edge[:, 1], edge[:, 0]], axis=1)
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    incoming = np.roll(edge, 1, axis=0)  # (8, 2) edge arriving at vertex i
    convex = orientation * _cross(incoming, edge) > 0
    return v, inward, convex


def candidate_contacts(spacing: float = 10.0, corner_directions: int = 3,
                       radius: float = geo.AGENT_RADIUS, fit_margin: float = 2.0) -> Contacts:
    """Contacts along every edge about ``spacing`` apart, plus ``corner_directions`` directions
    strictly inside each convex corner's range.

    Points near the two inside corners are dropped unless the pusher (``radius``) fits there
    with ``fit_margin`` to spare, i.e. unless a pusher touching the contact clears the rest
    of the T.
    """
    if spacing <= 0 or corner_directions < 0:
        raise ValueError(f"need spacing > 0 and corner_directions >= 0, got {spacing!r}, {corner_directions!r}")
    v, inward, convex = outline_corners()
    n_v = len(v)
    points, normals, corner = [], [], []
    for i in range(n_v):
        a, b = v[i], v[(i + 1) % n_v]
        length = float(np.linalg.norm(b - a))
        n_pts = max(2, int(round(length / spacing)) + 1)
        t = np.linspace(0.0, 1.0, n_pts)[:, None]  # (n, 1) includes both end corners
        pts = a + t * (b - a)
        points.append(pts)
        normals.append(np.repeat(inward[i][None], n_pts, axis=0))
        corner.append(np.zeros(n_pts, dtype=bool))
    for i in np.flatnonzero(convex):
        n_in, n_out = inward[i - 1], inward[i]  # normals of the edges meeting at vertex i
        start = math.atan2(n_in[1], n_in[0])
        turn = math.atan2(_cross(n_in, n_out), float(n_in @ n_out))
        for f in np.arange(1, corner_directions + 1) / (corner_directions + 1):
            ang = start + f * turn
            points.append(v[i][None])
            normals.append(np.array([[math.cos(ang), math.sin(ang)]]))
            corner.append(np.ones(1, dtype=bool))
    point = np.concatenate(points)  # (M, 2)
    normal = np.concatenate(normals)
    is_corner = np.concatenate(corner)
    # The pusher touching the contact must not overlap any other part of the T.
    touching = point - normal * (radius + fit_margin)
    fits = point_distance(touching) >= radius + fit_margin - 1e-6
    # Edge samples duplicate each other at shared corners: keep one.
    keep = fits & _first_occurrence(point, normal)
    point, normal, is_corner = point[keep], normal[keep], is_corner[keep]
    lever = _cross(point - _COG, normal)
    return Contacts(point=point, normal=normal, lever=lever, corner=is_corner)


def _first_occurrence(point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    key = np.round(np.concatenate([point, normal * 1e3], axis=1), 6)
    _, first = np.unique(key, axis=0, return_index=True)
    mask = np.zeros(len(point), dtype=bool)
    mask[first] = True
    return mask


# --------------------------------------------------------------------------------------------
# The push model
# --------------------------------------------------------------------------------------------
def predict_pushes(pose, contacts: Contacts, depths: np.ndarray,
                   mass: float = geo.T_MASS, moment: float = geo.T_MOMENT) -> np.ndarray:
    """Predicted block poses (M, D, 3) after pushing each contact (M) by each depth (D,).

    Per unit of pusher travel along the normal n (body frame) at lever k, the centre of
    gravity moves s = 1 / (1 + m k^2 / I) along n and the body turns by w = m s k / I. Holding
    this body-frame twist for the whole depth d moves the T along an arc (the SE(2)
    exponential): the CoG moves by V(w d) s n d in the body frame, V the usual arc matrix.
    """
    x, y, a = (float(v) for v in pose)
    depths = np.asarray(depths, dtype=np.float64)
    s = 1.0 / (1.0 + mass * contacts.lever**2 / moment)  # (M,)
    w = mass * s * contacts.lever / moment  # (M,) radians per unit depth
    phi = w[:, None] * depths[None, :]  # (M, D) total turn
    small = np.abs(phi) < 1e-9
    safe = np.where(small, 1.0, phi)
    sinc = np.where(small, 1.0, np.sin(safe) / safe)  # V = [[sinc, -cosc], [cosc, sinc]]
    cosc = np.where(small, 0.0, (1.0 - np.cos(safe)) / safe)
    vx = (s * contacts.normal[:, 0])[:, None] * depths  # (M, D) straight-line CoG move
    vy = (s * contacts.normal[:, 1])[:, None] * depths
    dx_body, dy_body = sinc * vx - cosc * vy, cosc * vx + sinc * vy  # (M, D)
    c, sn = math.cos(a), math.sin(a)
    cog = np.array([x, y]) + np.array([c * _COG[0] - sn * _COG[1], sn * _COG[0] + c * _COG[1]])
    cog_x = cog[0] + c * dx_body - sn * dy_body  # (M, D) new CoG, world
    cog_y = cog[1] + sn * dx_body + c * dy_body
    new_a = a + phi
    cn, sn2 = np.cos(new_a), np.sin(new_a)
    ox = cog_x - (cn * _COG[0] - sn2 * _COG[1])  # body origin = CoG - R(new angle) cog_local
    oy = cog_y - (sn2 * _COG[0] + cn * _COG[1])
    return np.stack([ox, oy, new_a], axis=-1)  # (M, D, 3)
