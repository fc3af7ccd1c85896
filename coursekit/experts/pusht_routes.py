"""Getting the pusher to a contact without touching the T: routes round the block, and a
smooth, person-like speed profile along them.

A route starts where the pusher is and ends at the approach point of the chosen push. If the
straight line keeps clear of the T, it is taken. Otherwise the pusher goes round the T through
waypoints placed beside the T's six convex corners (the corners of its convex hull, pushed
out along the corner's bisector), once clockwise and once anticlockwise (as seen on screen,
y down). Both ways are real options: when their lengths are close, the planner lets a seeded
coin choose, which is where the demonstrations become multimodal on purpose.

Everything geometric happens in the T's body frame, where the T is fixed (see
``pusht_clearance``); routes are returned in world coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht_geometry import local_to_world
from coursekit.experts.pusht_clearance import point_distance, segment_distance
from coursekit.experts.pusht_push_model import outline_corners

CLOCKWISE, ANTICLOCKWISE, STRAIGHT = "cw", "ccw", "straight"


@dataclass(frozen=True)
class Route:
    """A collision-free polyline for the pusher's centre.

    points: (K, 2) world coordinates, start first, approach point last.
    side: "straight", "cw" or "ccw" (screen orientation, y down).
    length: path length in pixels.
    """

    points: np.ndarray
    side: str
    length: float


class RoutePlanner:
    """Shortest routes round the T, one per direction (body-frame geometry, world output).

    Args:
        clearance: the distance the pusher's centre keeps from the T while travelling
            (pusher radius plus a margin).
        waypoint_clearance: how far beside each convex corner the waypoints sit (a little more
            than ``clearance``, so that the legs between them stay legal).
        arena: (lo, hi) box the waypoints must lie in (targets outside are clipped by the env).
    """

    def __init__(self, clearance: float, waypoint_clearance: float,
                 arena: tuple[float, float] = (0.0, geo.WORLD_SIZE)):
        if not 0 < clearance <= waypoint_clearance:
            raise ValueError(f"need 0 < clearance <= waypoint_clearance, got {clearance!r}, {waypoint_clearance!r}")
        self.clearance = float(clearance)
        self.arena = arena
        v, inward, convex = outline_corners()
        # Waypoint beside convex corner i: out along both edges' outward normals, so it sits
        # ``waypoint_clearance`` from both edge lines (the T's corners are right angles).
        out = -(inward + np.roll(inward, 1, axis=0))  # (8, 2) sum of the two outward normals
        self.waypoints = (v + out * waypoint_clearance)[convex]  # (W, 2), outline order
        n_w = len(self.waypoints)
        if segment_distance(self.waypoints, np.roll(self.waypoints, -1, axis=0)).min() < self.clearance - 1e-6:
            raise ValueError(f"waypoint_clearance {waypoint_clearance} leaves hull legs closer than {clearance}")
        # Legs between neighbouring waypoints run along the convex hull (checked just above).
        # chain[d, i, j]: length from waypoint i to j walking direction d (0: outline order, which
        # is clockwise on screen; 1: the reverse), through every waypoint in between; sweep[d, i, j]:
        # the signed angle that walk turns about the centre of gravity (> 0: clockwise on screen).
        leg = np.linalg.norm(np.roll(self.waypoints, -1, axis=0) - self.waypoints, axis=1)  # (W,)
        self.centre = np.asarray(geo.T_COG_LOCAL, dtype=np.float64)
        turn = _sweep(self.waypoints, np.roll(self.waypoints, -1, axis=0), self.centre)  # (W,) all > 0
        cum_len = np.concatenate([[0.0], np.cumsum(leg)])  # (W+1,)
        cum_turn = np.concatenate([[0.0], np.cumsum(turn)])
        i, j = np.meshgrid(np.arange(n_w), np.arange(n_w), indexing="ij")
        same = i == j
        fwd_len = np.where(same, 0.0, (cum_len[j] - cum_len[i]) % cum_len[-1])  # (W, W)
        fwd_turn = np.where(same, 0.0, (cum_turn[j] - cum_turn[i]) % cum_turn[-1])
        self._chain = np.stack([fwd_len, np.where(same, 0.0, cum_len[-1] - fwd_len)])  # (2, W, W)
        self._sweep = np.stack([fwd_turn, np.where(same, 0.0, fwd_turn - cum_turn[-1])])

    # ----------------------------------------------------------------------------------------
    def _visible(self, a: np.ndarray, b: np.ndarray, start_clearance: np.ndarray) -> np.ndarray:
        """Whether straight legs a -> b (..., 2) keep clear. A leg leaving (or reaching) a point
        closer than ``clearance`` (the pusher just backed off) only has to keep that point's own
        clearance."""
        return segment_distance(a, b) >= np.minimum(self.clearance, start_clearance) - 0.5

    def _round_the_t(self, pose, start: np.ndarray, goals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Best routes round the T to M goals (M, 2) from ``start`` (2,) (body frame).

        Returns lengths (2, M) [cw, ccw] (inf: none) and the (2, M, 2) waypoint indices
        (entry, exit) of each. A route start -> wp i -> ... -> wp j -> goal counts as clockwise
        when its total sweep about the centre of gravity is positive: entering and leaving at
        the same waypoint is a real route too, and belongs to exactly one side.
        """
        wp = self.waypoints
        n_w, n_g = len(wp), len(goals)
        lo, hi = self.arena
        wp_world = local_to_world(wp, pose)
        in_arena = np.all((wp_world >= lo) & (wp_world <= hi), axis=1)  # (W,)
        vis_start = self._visible(start, wp, point_distance(start)) & in_arena  # (W,)
        vis_goal = self._visible(wp[None], goals[:, None], point_distance(goals)[:, None]) & in_arena  # (M, W)
        to_wp = np.where(vis_start, np.linalg.norm(wp - start, axis=1), np.inf)  # (W,)
        from_wp = np.where(vis_goal, np.linalg.norm(wp[None] - goals[:, None], axis=2), np.inf)  # (M, W)
        # total[d, m, i, j] = start -> wp i -> (chain, direction d) -> wp j -> goal m
        total = to_wp[None, None, :, None] + self._chain[:, None] + from_wp[None, :, None, :]  # (2, M, W, W)
        sweep = (_sweep(start, wp, self.centre)[None, None, :, None] + self._sweep[:, None]
                 + _sweep(wp[None], goals[:, None], self.centre)[None, :, None, :])  # (2, M, W, W)
        right_way = np.stack([sweep[0] > 0, sweep[1] < 0])  # (2, M, W, W)
        total = np.where(right_way, total, np.inf).reshape(2, n_g, n_w * n_w)  # (2, M, W*W)
        best = total.argmin(-1)  # (2, M)
        lengths = np.take_along_axis(total, best[..., None], -1)[..., 0]  # (2, M)
        return lengths, np.stack(np.unravel_index(best, (n_w, n_w)), axis=-1)  # (2, M, 2)

    def lengths(self, pose, start_local: np.ndarray, goals_local: np.ndarray) -> np.ndarray:
        """Route lengths (3, M) to M goals (M, 2) from one start (2,), body frame, rows
        [straight, cw, ccw]; inf where that kind of route does not exist."""
        goals = np.asarray(goals_local, dtype=np.float64).reshape(-1, 2)  # (M, 2)
        start = np.asarray(start_local, dtype=np.float64)
        out = np.full((3, len(goals)), np.inf)
        clear = self._visible(start, goals, np.minimum(point_distance(start), point_distance(goals)))
        out[0] = np.where(clear, np.linalg.norm(goals - start, axis=1), np.inf)
        out[1:] = self._round_the_t(pose, start, goals)[0]
        return out

    def route(self, pose, start_local: np.ndarray, goal_local: np.ndarray, side: str) -> Route:
        """The shortest ``side`` route ("straight", "cw" or "ccw") as a world polyline."""
        start = np.asarray(start_local, dtype=np.float64)
        goal = np.asarray(goal_local, dtype=np.float64)
        if side == STRAIGHT:
            pts = np.stack([start, goal])
        elif side in (CLOCKWISE, ANTICLOCKWISE):
            d = 0 if side == CLOCKWISE else 1
            lengths, ends = self._round_the_t(pose, start, goal[None])
            if not np.isfinite(lengths[d, 0]):
                raise ValueError(f"no {side} route from {start} to {goal} (body frame)")
            i, j = ends[d, 0]
            step, chain = (1 if d == 0 else -1), [int(i)]
            while chain[-1] != j:
                chain.append((chain[-1] + step) % len(self.waypoints))
            pts = np.concatenate([start[None], self.waypoints[chain], goal[None]])
        else:
            raise ValueError(f"side must be 'straight', 'cw' or 'ccw', got {side!r}")
        world = local_to_world(pts, pose)  # (K, 2)
        length = float(np.linalg.norm(np.diff(world, axis=0), axis=1).sum())
        return Route(points=world, side=side, length=length)


def _sweep(a: np.ndarray, b: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Signed angle (...,) from a to b (..., 2) seen from ``centre``, in (-pi, pi]."""
    u, v = a - centre, b - centre
    return np.arctan2(u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0], (u * v).sum(-1))


# --------------------------------------------------------------------------------------------
# Driving a route: 10 Hz targets with a speed limit, gentle turns and a soft stop
# --------------------------------------------------------------------------------------------
def speed_profile_targets(points: np.ndarray, max_speed: float, accel: float, turn_speed: float,
                          start_speed: float = 0.0) -> np.ndarray:
    """Targets (T, 2) along the polyline ``points`` (K, 2), one per env step, ending exactly at
    the last point.

    The pusher follows its target through a critically damped PD law, lagging about two steps
    behind at full speed, so the profile (like a person's hand) speeds up at most ``accel``
    px/step^2, cruises at ``max_speed`` px/step, slows to ``turn_speed`` at sharp corners
    (where the lagging pusher would cut the corner towards the block) and comes to a stop at
    the end.
    """
    pts = np.asarray(points, dtype=np.float64)
    seg = np.diff(pts, axis=0)  # (K-1, 2)
    seg_len = np.linalg.norm(seg, axis=1)
    keep = seg_len > 1e-9
    if not keep.any():
        return np.empty((0, 2))
    pts = np.concatenate([pts[:1], pts[1:][keep]])
    seg, seg_len = seg[keep], seg_len[keep]
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])  # (K,) arclength of each vertex
    total = float(cum[-1])
    # Speed allowed at each vertex: full speed on gentle bends, turn_speed at right angles.
    unit = seg / seg_len[:, None]
    cos_turn = (unit[:-1] * unit[1:]).sum(1)  # (K-2,)
    bend = np.clip((1.0 - cos_turn) / (1.0 - math.cos(math.pi / 2)), 0.0, 1.0)  # 0 straight, 1 at 90 deg
    v_vertex = np.concatenate([max_speed - bend * (max_speed - turn_speed), [0.0]])  # (K-1,) vertices 1..K-1
    s_vertex = cum[1:]
    s, v, out = 0.0, float(start_speed), []
    while total - s > 1e-6:
        ahead = s_vertex >= s - 1e-9
        # Fastest step v after which every vertex ahead can still be reached at its limit:
        # v^2 + 2 a v <= v_j^2 + 2 a (s_j - s)  (braking by ``accel`` per step from then on).
        room = v_vertex[ahead] ** 2 + 2.0 * accel * np.maximum(s_vertex[ahead] - s, 0.0)
        brake = float((np.sqrt(accel**2 + room) - accel).min())
        v = max(min(v + accel, max_speed, brake), min(1.0, total - s))
        s = min(s + v, total)
        k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        out.append(pts[k] + unit[k] * (s - cum[k]))
    return np.asarray(out)  # (T, 2)
