"""How far is a point, or a straight move, from the T? (body-local frame, pure numpy)

The scripted PushT expert (``pusht_planner``) works in the block's own frame wherever it can:
there the T never moves, it is the union of two axis-aligned boxes (crossbar and stem, see
``pusht_geometry``), and distances are a few lines of numpy. A pusher of radius r centred at
p touches the T exactly when ``point_distance(p) <= r``; a straight move from a to b keeps
clear of the T when ``segment_distance(a, b) > r``.

Every function takes points in the T's body-local frame (``pusht_geometry.world_to_local``
converts) and is vectorised over leading dimensions.
"""

from __future__ import annotations

import numpy as np

from coursekit.envs import pusht_geometry as geo


def _boxes() -> tuple[np.ndarray, np.ndarray]:
    """(2, 2) lower and (2, 2) upper corners of the crossbar and stem boxes (local frame)."""
    boxes = np.stack([geo.CROSSBAR_LOCAL, geo.STEM_LOCAL])  # (2, 4, 2)
    return boxes.min(axis=1), boxes.max(axis=1)


def point_distance(points: np.ndarray) -> np.ndarray:
    """Distance (...,) from local points (..., 2) to the T (0 inside it)."""
    lo, hi = _boxes()
    p = np.asarray(points, dtype=np.float64)[..., None, :]  # (..., 1, 2) against 2 boxes
    gap = np.maximum(np.maximum(lo - p, p - hi), 0.0)  # (..., 2, 2) per box, per axis
    return np.sqrt((gap**2).sum(-1)).min(-1)


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (...,) from points p (..., 2) to segments a-b (..., 2) (broadcasting)."""
    ab = b - a
    t = ((p - a) * ab).sum(-1) / np.maximum((ab**2).sum(-1), 1e-12)
    closest = a + np.clip(t, 0.0, 1.0)[..., None] * ab
    return np.sqrt(((p - closest) ** 2).sum(-1))


def _segment_hits_box(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether segments a-b (..., 2) cross the box [lo, hi] (2,) (slab test), (...,) bool."""
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - a) / d
        t2 = (hi - a) / d
    t_near = np.where(d == 0, -np.inf, np.minimum(t1, t2))  # (..., 2)
    t_far = np.where(d == 0, np.inf, np.maximum(t1, t2))
    # An axis the segment does not move along: inside the slab or never.
    inside = (a >= lo) & (a <= hi)
    slab_ok = np.where(d == 0, inside, True).all(-1)
    t0 = np.maximum(t_near.max(-1), 0.0)
    t_end = np.minimum(t_far.min(-1), 1.0)
    return slab_ok & (t0 <= t_end)


def segment_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest distance (...,) between the T and the straight moves a -> b (..., 2) (local).

    For a segment and a convex box that do not intersect, the closest pair always involves a
    corner of one of them, so four corner-to-segment and two endpoint-to-box distances suffice.
    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    lo, hi = _boxes()
    best = np.minimum(point_distance(a), point_distance(b))
    for k in range(lo.shape[0]):
        corners = np.array([[lo[k, 0], lo[k, 1]], [hi[k, 0], lo[k, 1]],
                            [hi[k, 0], hi[k, 1]], [lo[k, 0], hi[k, 1]]])  # (4, 2)
        d_corner = _point_segment_distance(corners, a[..., None, :], b[..., None, :]).min(-1)
        best = np.minimum(best, np.where(_segment_hits_box(a, b, lo[k], hi[k]), 0.0, d_corner))
    return best

