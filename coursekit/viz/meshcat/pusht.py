"""PushT in 3-D with meshcat: an extruded T, a pusher cylinder, the goal T, and rollouts as animations.

The 2-D world (512 x 512 units, y DOWN, see ``coursekit.envs.pusht_geometry``) is laid on the
floor of meshcat's z-up world, 1 unit = 1/512 m, centred on the origin::

    meshcat (x, y) = ((u - 256) / 512, (256 - v) / 512)        for a PushT point (u, v)

Flipping y makes the top-down 3-D view look exactly like the 2-D images (y down on screen). A
flip turns rotations around: the body pose (u, v, angle) becomes a rotation of -angle about z,
and body-local points (lx, ly) become (lx, -ly) (because F R(a) F = R(-a) for F = diag(1, -1)).

The scene (colours of the 2-D renderer, which follow the reference): a white arena with light
grey walls, the goal T as a flat light-green slab with a darker outline, the block as two slate
grey boxes (crossbar and stem) extruded T_SCALE units tall, the pusher as a royal-blue cylinder,
and (optionally) the commanded target as a small crimson disc.
"""

from __future__ import annotations

import os
from pathlib import Path

import meshcat.geometry as g
import numpy as np
from meshcat.animation import Animation

from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht_render import AGENT_COLOR, BLOCK_COLOR, BLOCK_OUTLINE, GOAL_COLOR, TARGET_COLOR, WALL_COLOR
from coursekit.tasks.pusht import PUSHT
from coursekit.viz.meshcat.scene import MeshcatScene, pose_matrix, shared_scene, translation

UNIT = 1.0 / geo.WORLD_SIZE
"""Metres per PushT unit: the arena is 1 m across."""
BLOCK_HEIGHT = geo.T_SCALE
"""Extrusion height of the T, in PushT units (as tall as its bars are wide)."""
AGENT_HEIGHT = 1.5 * geo.T_SCALE
"""Height of the pusher cylinder, in PushT units (a bit taller than the T, so it reads as a tool)."""
GOAL_HEIGHT = 1.0
"""Thickness of the goal slab, in PushT units (flat on the floor)."""
ROOT = "pusht"
"""meshcat path under which the scene lives."""


def _rgb(c: tuple[int, int, int]) -> int:
    return (c[0] << 16) | (c[1] << 8) | c[2]


def to_meshcat_xy(points: np.ndarray) -> np.ndarray:
    """PushT world points (..., 2) in units, y down -> meshcat floor points (..., 2) in metres, y up."""
    p = np.asarray(points, dtype=np.float64)
    half = geo.WORLD_SIZE / 2
    return np.stack([(p[..., 0] - half) * UNIT, (half - p[..., 1]) * UNIT], axis=-1)  # (..., 2)


def body_transform(pose) -> np.ndarray:
    """(4, 4) meshcat transform of the block's body frame for a PushT pose (x, y, angle).

    Children of this frame are drawn in *flipped* local coordinates (lx, -ly) * UNIT.
    """
    x, y, angle = (float(v) for v in pose)
    c, s = np.cos(-angle), np.sin(-angle)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    xy = to_meshcat_xy(np.array([x, y]))
    return pose_matrix([xy[0], xy[1], 0.0], rot)


def _check_states(states) -> np.ndarray:
    s = np.asarray(states, dtype=np.float64)
    if s.ndim == 1:
        s = s[None]  # (1, D)
    if s.ndim != 2 or s.shape[1] not in (5, 7) or len(s) == 0:
        raise ValueError(f"states must have shape (T, 5) or (T, 7) = [ax, ay, bx, by, angle, ...] with T >= 1, "
                         f"got shape {np.shape(states)}")
    if not np.all(np.isfinite(s)):
        bad = np.argwhere(~np.isfinite(s))[0]
        raise ValueError(f"states must be finite, got {s[tuple(bad)]} at step {bad[0]}, column {bad[1]}")
    return s


def _box_in_body(corners_local: np.ndarray, height: float) -> tuple[g.Box, np.ndarray]:
    """A meshcat Box for an axis-aligned body-local rectangle (4, 2), and its offset in the body frame."""
    lo, hi = corners_local.min(axis=0), corners_local.max(axis=0)
    size = np.array([hi[0] - lo[0], hi[1] - lo[1], height]) * UNIT
    centre = (lo + hi) / 2
    return g.Box(size.tolist()), translation([centre[0] * UNIT, -centre[1] * UNIT, height * UNIT / 2])


def _outline(points_xy: np.ndarray, z: float, color: int) -> g.LineLoop:
    """A closed polyline through meshcat floor points (N, 2) at height z."""
    pts = np.column_stack([points_xy, np.full(len(points_xy), z)]).T.astype(np.float32)  # (3, N)
    return g.LineLoop(g.PointsGeometry(pts), g.LineBasicMaterial(color=color))


class PushTMeshcat:
    """The PushT scene in a meshcat viewer: show a state, or record a rollout as an animation.

    >>> viewer = PushTMeshcat()                         # doctest: +SKIP
    >>> viewer.animate(dataset.episode(0)["state"])     # (T, 5) states at 10 Hz
    >>> viewer.save_html("outputs/pusht_rollout.html")  # one self-contained file

    Args:
        scene: the :class:`MeshcatScene` to draw in (default: the process's shared one). The
            scene is cleared: one viewer owns the scene at a time.
        show_target: also draw the commanded pusher target (needs ``actions`` in :meth:`animate`).
    """

    def __init__(self, scene: MeshcatScene | None = None, show_target: bool = True) -> None:
        self.scene = shared_scene() if scene is None else scene
        self.show_target = show_target
        self._build()

    # -- the static scene ------------------------------------------------------------------------
    def _build(self) -> None:
        scene = self.scene
        scene.clear()
        scene.hide_grid_and_axes()
        scene.set_background([0.93, 0.95, 0.97], [0.80, 0.84, 0.89])
        vis = scene.vis[ROOT]
        flat = g.MeshLambertMaterial  # matte: reads like the 2-D renderer, no glare

        # the arena floor (white) just below z = 0, and the four walls
        vis["floor"].set_object(g.Box([1.0, 1.0, 0.004]), flat(color=0xFFFFFF))
        vis["floor"].set_transform(translation([0, 0, -0.002]))
        lo, hi, r = geo.WALL_LO, geo.WALL_HI, geo.WALL_RADIUS
        length, thick, tall = (hi - lo + 2 * r) * UNIT, 2 * r * UNIT, 10 * UNIT
        for name, (u, v), horizontal in [("north", ((lo + hi) / 2, lo), True), ("south", ((lo + hi) / 2, hi), True),
                                         ("west", (lo, (lo + hi) / 2), False), ("east", (hi, (lo + hi) / 2), False)]:
            size = [length, thick, tall] if horizontal else [thick, length, tall]
            xy = to_meshcat_xy(np.array([u, v]))
            vis["walls"][name].set_object(g.Box(size), flat(color=_rgb(WALL_COLOR)))
            vis["walls"][name].set_transform(translation([xy[0], xy[1], tall / 2]))

        # the goal: a flat light-green T with a darker outline, fixed at GOAL_POSE
        goal = vis["goal"]
        goal.set_transform(body_transform(geo.GOAL_POSE))
        for name, corners in (("crossbar", geo.CROSSBAR_LOCAL), ("stem", geo.STEM_LOCAL)):
            box, offset = _box_in_body(corners, GOAL_HEIGHT)
            goal[name].set_object(box, flat(color=_rgb(GOAL_COLOR)))
            goal[name].set_transform(offset)
        outline_local = geo.T_OUTLINE_LOCAL * [UNIT, -UNIT]  # (8, 2) flipped body-local, metres
        goal["outline"].set_object(_outline(outline_local, 1.5 * GOAL_HEIGHT * UNIT, 0x2E8B57))

        # the block: crossbar + stem extruded BLOCK_HEIGHT, with its outline on top
        block = vis["block"]
        for name, corners in (("crossbar", geo.CROSSBAR_LOCAL), ("stem", geo.STEM_LOCAL)):
            box, offset = _box_in_body(corners, BLOCK_HEIGHT)
            block[name].set_object(box, flat(color=_rgb(BLOCK_COLOR)))
            block[name].set_transform(offset)
        block["outline"].set_object(_outline(outline_local, BLOCK_HEIGHT * UNIT * 1.001, _rgb(BLOCK_OUTLINE)))

        # the pusher: a cylinder standing on the floor (meshcat cylinders run along y: turn to z)
        agent = vis["agent"]
        stand_up = pose_matrix([0, 0, AGENT_HEIGHT * UNIT / 2], [[1, 0, 0], [0, 0, -1], [0, 1, 0]])
        agent["body"].set_object(g.Cylinder(AGENT_HEIGHT * UNIT, geo.AGENT_RADIUS * UNIT),
                                 flat(color=_rgb(AGENT_COLOR)))
        agent["body"].set_transform(stand_up)
        if self.show_target:
            target = vis["target"]
            disc = pose_matrix([0, 0, 0.5 * UNIT], [[1, 0, 0], [0, 0, -1], [0, 1, 0]])
            target["disc"].set_object(g.Cylinder(1.0 * UNIT, 5.0 * UNIT), flat(color=_rgb(TARGET_COLOR)))
            target["disc"].set_transform(disc)
            target.set_property("visible", False)  # shown once there is an action to show

        # a camera on the south side, 65 deg up: the arena (1 m square) fills the window
        scene.frame(radius=0.52, elevation_deg=65.0)

    # -- poses -------------------------------------------------------------------------------------
    @staticmethod
    def transforms(state, action=None) -> dict[str, np.ndarray]:
        """meshcat transforms (4, 4) of the moving parts for one state [ax, ay, bx, by, angle, ...].

        Keys: "agent", "block" and, when ``action`` (2,) is given, "target".
        """
        s = np.asarray(state, dtype=np.float64)
        agent_xy = to_meshcat_xy(s[0:2])
        out = {"agent": translation([agent_xy[0], agent_xy[1], 0.0]), "block": body_transform(s[2:5])}
        if action is not None:
            target_xy = to_meshcat_xy(np.asarray(action, dtype=np.float64))
            out["target"] = translation([target_xy[0], target_xy[1], 0.0])
        return out

    def show_state(self, state, action=None) -> None:
        """Put the pusher, the block (and the target) at one state (5,) or (7,)."""
        s = _check_states(state)[0]
        action = action if self.show_target else None
        for name, tf in self.transforms(s, action).items():
            self.scene.vis[ROOT][name].set_transform(tf)
        if action is not None:
            self.scene.vis[ROOT]["target"].set_property("visible", True)

    def animate(self, states, actions=None, fps: float = PUSHT.control_hz, play: bool = True, repetitions: int = 1) -> Animation:
        """Record a rollout as a meshcat animation (one keyframe per step) and load it in the scene.

        Args:
            states: (T, 5) or (T, 7) [agent_x, agent_y, block_x, block_y, block_angle, ...] in
                PushT units (a dataset episode's "state" or stacked ``env.get_state()``).
            actions: optional (T, 2) commanded pusher targets, drawn as a crimson disc.
            fps: playback rate (default: PushT's control rate, ``PUSHT.control_hz``).
            play: start playing when the page opens (False: the page shows the first step).
            repetitions: how many times the animation plays.

        The scene's static transforms are set to the FIRST step too, so the page shows a
        sensible picture before (and without) playing.
        """
        s = _check_states(states)
        if actions is not None:
            actions = np.asarray(actions, dtype=np.float64)
            if actions.shape != (len(s), 2) or not np.all(np.isfinite(actions)):
                raise ValueError(f"actions must be finite with shape ({len(s)}, 2), got shape {actions.shape}")
        if not fps > 0:
            raise ValueError(f"fps must be positive, got {fps}")
        if repetitions < 1:
            raise ValueError(f"repetitions must be >= 1, got {repetitions}")
        self.show_state(s[0], None if actions is None else actions[0])
        anim = Animation(default_framerate=fps)
        for i in range(len(s)):
            with anim.at_frame(self.scene.vis, i) as frame:
                action = actions[i] if actions is not None and self.show_target else None
                for name, tf in self.transforms(s[i], action).items():
                    frame[ROOT][name].set_transform(tf)
        self.scene.vis.set_animation(anim, play=play, repetitions=repetitions)
        return anim

    # -- export ------------------------------------------------------------------------------------
    def html(self) -> str:
        """The scene (and its animation) as one self-contained HTML page."""
        return self.scene.static_html()

    def save_html(self, path: str | os.PathLike) -> Path:
        """Write :meth:`html` to ``path`` atomically; return the path."""
        return self.scene.save_html(path)


def export_pusht_rollout(states, path: str | os.PathLike, actions=None, fps: float = PUSHT.control_hz, play: bool = True,
                         scene: MeshcatScene | None = None) -> Path:
    """One call: draw PushT, record ``states`` (T, 5|7) (and ``actions`` (T, 2)) and write the HTML."""
    viewer = PushTMeshcat(scene, show_target=actions is not None)
    viewer.animate(states, actions=actions, fps=fps, play=play)
    return viewer.save_html(path)
