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
from coursekit.experts.pusht_clearance import local_to_world, point_distance, segment_distance
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
        # Legs between neighbouring waypoints run along the convex hull: always clear.
        leg = np.linalg.norm(np.roll(self.waypoints, -1, axis=0) - self.waypoints, axis=1)  # (W,)
        if segment_distance(self.waypoints, np.roll(self.waypoints, -1, axis=0)).min() < self.clearance - 1e-6:
            raise ValueError(f"waypoint_clearance {waypoint_clearance} leaves hull legs closer than {clearance}")
        # chain[d, i, j]: length from waypoint i to j walking direction d (0: outline order = cw
        # on screen, 1: reverse = ccw), through every waypoint in between.
        cum = np.concatenate([[0.0], np.cumsum(leg)])  # (W+1,)
        i, j = np.meshgrid(np.arange(n_w), np.arange(n_w), indexing="ij")
        forward = (cum[j] - cum[i]) % cum[-1]  # (W, W)
        forward = np.where(i == j, 0.0, forward)
        backward = np.where(i == j, 0.0, cum[-1] - forward)
        self._chain = np.stack([forward, backward])  # (2, W, W)

    # ----------------------------------------------------------------------------------------
    def _visible(self, a: np.ndarray, b: np.ndarray, start_clearance: np.ndarray) -> np.ndarray:
        """Whether straight legs a -> b (..., 2) keep clear. A leg leaving (or reaching) a point
        closer than ``clearance`` (the pusher just backed off) only has to keep that point's own
        clearance."""
        return segment_distance(a, b) >= np.minimum(self.clearance, start_clearance) - 0.5

    def lengths(self, pose, start_local: np.ndarray, goals_local: np.ndarray) -> np.ndarray:
        """Route lengths (3, M) to M goals (M, 2) from one start (2,), body frame, rows
        [straight, cw, ccw]; inf where that kind of route does not exist."""
        goals_local = np.asarray(goals_local, dtype=np.float64)
        start = np.asarray(start_local, dtype=np.float64)
        d_start = point_distance(start)
        d_goals = point_distance(goals_local)  # (M,)
        out = np.full((3, len(goals_local)), np.inf)
        direct = np.linalg.norm(goals_local - start, axis=1)  # (M,)
        clear = self._visible(start, goals_local, np.minimum(d_start, d_goals))
        out[0] = np.where(clear, direct, np.inf)
        wp_world = local_to_world(self.waypoints, pose)  # (W, 2)
        lo, hi = self.arena
        in_arena = np.all((wp_world >= lo) & (wp_world <= hi), axis=1)  # (W,)
        vis_start = self._visible(start, self.waypoints, d_start) & in_arena  # (W,)
        vis_goal = self._visible(self.waypoints[None], goals_local[:, None], d_goals[:, None]) & in_arena  # (M, W)
        to_wp = np.where(vis_start, np.linalg.norm(self.waypoints - start, axis=1), np.inf)  # (W,)
        from_wp = np.where(vis_goal, np.linalg.norm(self.waypoints[None] - goals_local[:, None], axis=2), np.inf)
        # total[d, m, i, j] = start -> wp i -> (chain, direction d) -> wp j -> goal m
        total = to_wp[None, None, :, None] + self._chain[:, None] + from_wp[None, :, None, :]  # (2, M, W, W)
        out[1:] = total.reshape(2, len(goals_local), -1).min(-1)  # (2, M)
        return out

    def route(self, pose, start_local: np.ndarray, goal_local: np.ndarray, side: str) -> Route:
        """The shortest ``side`` route ("straight", "cw" or "ccw") as a world polyline."""
        start = np.asarray(start_local, dtype=np.float64)
        goal = np.asarray(goal_local, dtype=np.float64)
        if side == STRAIGHT:
            pts = np.stack([start, goal])
        elif side in (CLOCKWISE, ANTICLOCKWISE):
            d = 0 if side == CLOCKWISE else 1
            wp = self.waypoints
            n_w = len(wp)
            wp_world = local_to_world(wp, pose)
            lo, hi = self.arena
            in_arena = np.all((wp_world >= lo) & (wp_world <= hi), axis=1)
            vis_s = self._visible(start, wp, point_distance(start)) & in_arena
            vis_g = self._visible(wp, goal, point_distance(goal)) & in_arena
            to_wp = np.where(vis_s, np.linalg.norm(wp - start, axis=1), np.inf)
            from_wp = np.where(vis_g, np.linalg.norm(wp - goal, axis=1), np.inf)
            total = to_wp[:, None] + self._chain[d] + from_wp[None, :]  # (W, W)
            i, j = np.unravel_index(int(np.argmin(total)), total.shape)
            if not np.isfinite(total[i, j]):
                raise ValueError(f"no {side} route from {start} to {goal} (body frame)")
            step = 1 if d == 0 else -1
            chain = [i]
            while chain[-1] != j:
                chain.append((chain[-1] + step) % n_w)
            pts = np.concatenate([start[None], wp[chain], goal[None]])
        else:
            raise ValueError(f"side must be 'straight', 'cw' or 'ccw', got {side!r}")
        world = local_to_world(pts, pose)  # (K, 2)
        length = float(np.linalg.norm(np.diff(world, axis=0), axis=1).sum())
        return Route(points=world, side=side, length=length)


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
