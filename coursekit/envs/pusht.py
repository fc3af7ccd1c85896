"""PushT on pymunk 7: push a T-shaped block onto a goal pose with a round pusher.

A re-implementation of the task used by the Diffusion Policy paper (its ``pusht_env.py``) and
by the gym-pusht package, keeping the reference semantics so that published PushT scores stay
comparable (the semantics below; geometry in ``pusht_geometry.py``):

- 512 x 512 world, y down; four static walls from (5, 5) to (506, 506), radius 2.
- Gravity 0 and ``space.damping = 0``: pymunk multiplies every dynamic body's velocity by
  damping ** dt = 0 each substep, so the T moves only while it is being pushed.
- The pusher is a KINEMATIC circle (radius 15): infinite mass, never deflected by the block and
  not stopped by the walls (it can shove the T out of the arena, as in the reference).
- Action = absolute target (x, y) for the pusher, at the task's control rate (``PUSHT.control_hz``,
  10 Hz): one env step = SIM_HZ / control_hz = 10 substeps of dt = 0.01; each substep applies the
  PD law v += (k_p (a - x) + k_v (0 - v)) dt with k_p = 100, k_v = 20, then ``space.step(dt)``.
  (Discrete critically-damped-ish tracking; the pusher lags its target.)
- coverage = area(goal T intersect block T) / area(goal T); reward = clip(coverage / 0.95, 0, 1);
  ``terminated`` when coverage > 0.95; ``truncated`` after ``max_episode_steps`` steps (default:
  the task's protocol, ``PUSHT.max_steps``).

Observations (``obs_type``):

- ``"state"``: (5,) float64 [agent_x, agent_y, block_x, block_y, block_angle mod 2 pi]
  (block_x/y = body origin, the middle of the crossbar's top edge, not the centre of gravity).
- ``"keypoints"``: (18,) float64 [agent_x, agent_y, k0x, k0y, ..., k7x, k7y] with the 8 T corners
  in the order of ``pusht_geometry.KEYPOINTS_LOCAL`` (crossbar (-60,30), (60,30), (60,0), (-60,0),
  then stem (-15,30), (15,30), (15,120), (-15,120)): gym-pusht's 8 corners (not the paper's 9),
  though gym-pusht lists the crossbar from the other end (``coursekit.data.lerobot_pusht``).
- ``"pixels"``: (H, W, 3) uint8 image, 96 x 96 by default (``obs_size``); the action target is
  never drawn into observations.
- ``"pixels_agent_pos"``: dict {"pixels": (H, W, 3) uint8, "agent_pos": (2,) float64}.

``info``: "coverage", "is_success" (coverage > 0.95), "block_pose" (3,) [x, y, angle unwrapped],
"agent_pos" (2,).

Departure from the reference (documented): out-of-range action targets are CLIPPED to [0, 512]
(the reference passes them through); NaN/inf or wrongly shaped actions raise ValueError.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pymunk
from gymnasium import spaces

from coursekit.envs import pusht_geometry as geo
from coursekit.envs.checks import check_reset_args, finite_array
from coursekit.envs.image_size import size_hw
from coursekit.tasks.pusht import PUSHT

OBS_TYPES = ("state", "keypoints", "pixels", "pixels_agent_pos")
RESET_OPTIONS = {"reset_to_state": "(5,) [ax, ay, bx, by, angle] start state (None: the seeded draw)"}

SIM_HZ = 100
"""Physics substeps per second (dt = 0.01); an env step is SIM_HZ / PUSHT.control_hz of them."""
K_P, K_V = 100.0, 20.0
"""PD gains of the pusher's tracking law (reference values)."""
MAX_START_ANGLE = 1000.0
"""Largest |angle| (rad) ``reset_to_state`` accepts: unwrapped demonstration angles stay within ~20 rad."""


def check_start(start: np.ndarray, name: str = "options['reset_to_state']") -> np.ndarray:
    """A (5,) start state [ax, ay, bx, by, angle] whose reset stays in the world, else ValueError naming it.

    The pusher and the block's (x, y) must lie in the 512 x 512 world (the observation space), the
    angle within +-MAX_START_ANGLE, and the block's origin where the LEGACY reset order puts it
    (``pusht_geometry.legacy_pose``: up to 90 px from (bx, by)) must lie in the world too, so the
    first observation is inside ``observation_space``.
    """
    w = geo.WORLD_SIZE
    for i, what in enumerate(("agent x", "agent y", "block x", "block y")):
        if not 0.0 <= start[i] <= w:
            raise ValueError(f"{name}: {what} must be in [0, {w:g}] (the world), got {float(start[i])!r}")
    if abs(start[4]) > MAX_START_ANGLE:
        raise ValueError(f"{name}: angle must be in [-{MAX_START_ANGLE:g}, {MAX_START_ANGLE:g}] rad, got {float(start[4])!r}")
    x, y, _ = geo.legacy_pose(start[2:4], float(start[4]))
    if not (0.0 <= x <= w and 0.0 <= y <= w):
        raise ValueError(f"{name}: the legacy reset order (see PushTEnv.reset) would put the block's origin at "
                         f"({x:.1f}, {y:.1f}), outside the [0, {w:g}] world; move (bx, by) inwards")
    return start


class PushTEnv(gym.Env):
    """The PushT task (gymnasium API), faithful to the reference semantics (see module doc).

    Args:
        obs_type: "state" | "keypoints" | "pixels" | "pixels_agent_pos".
        render_mode: None or "rgb_array" (``render()`` returns (H, W, 3) uint8 at ``render_size``,
            with the latest action target drawn as a small cross).
        render_size: size of ``render()`` images, int or (H, W).
        max_episode_steps: episode length before ``truncated`` (default: the protocol's, ``PUSHT.max_steps``).
        obs_size: size of pixel observations, int or (H, W) (reference: 96).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": PUSHT.control_hz}

    def __init__(self, obs_type: str = "state", render_mode: str | None = None,
                 render_size=96, max_episode_steps: int = PUSHT.max_steps, obs_size=96):
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {obs_type!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if not isinstance(max_episode_steps, (int, np.integer)) or max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be a positive int, got {max_episode_steps!r}")
        self.obs_type = obs_type
        self.render_mode = render_mode
        self.render_size = size_hw(render_size, "render_size")
        self.obs_size = size_hw(obs_size, "obs_size")
        self.max_episode_steps = int(max_episode_steps)
        self.goal_pose = geo.GOAL_POSE
        self.dt = 1.0 / SIM_HZ
        self.n_substeps = round(SIM_HZ / PUSHT.control_hz)

        self.action_space = spaces.Box(0.0, geo.WORLD_SIZE, shape=(2,), dtype=np.float64)
        self.observation_space = self._make_observation_space()

        self._scorer = geo.CoverageScorer(self.goal_pose)
        self._obs_renderer = None
        self._view_renderer = None
        if obs_type in ("pixels", "pixels_agent_pos"):
            from coursekit.envs.pusht_render import PushTRenderer

            self._obs_renderer = PushTRenderer(self.obs_size)
        self._steps = 0
        self._last_action: np.ndarray | None = None
        self._build_space()

    # ----------------------------------------------------------------------------------------
    # Spaces and the pymunk world
    # ----------------------------------------------------------------------------------------
    def _make_observation_space(self) -> spaces.Space:
        w = geo.WORLD_SIZE
        if self.obs_type == "state":
            # Bounds as in the reference; extreme pushes can carry the block beyond them.
            return spaces.Box(low=np.zeros(5), high=np.array([w, w, w, w, 2 * math.pi]),
                              dtype=np.float64)
        if self.obs_type == "keypoints":
            # The T's corners may lie outside the arena (the T can be shoved through a wall).
            low = np.concatenate([[0.0, 0.0], np.full(16, -w)])
            high = np.concatenate([[w, w], np.full(16, 2 * w)])
            return spaces.Box(low=low, high=high, dtype=np.float64)
        h, wd = self.obs_size
        pixels = spaces.Box(0, 255, shape=(h, wd, 3), dtype=np.uint8)
        if self.obs_type == "pixels":
            return pixels
        agent = spaces.Box(0.0, w, shape=(2,), dtype=np.float64)
        return spaces.Dict({"pixels": pixels, "agent_pos": agent})

    def _build_space(self) -> None:
        """A fresh pymunk world (the reference rebuilds it on every reset, which also clears
        pymunk's cached contacts so that a reset never depends on history)."""
        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.damping = 0.0  # velocities zeroed every substep: quasi-static pushing
        lo, hi = geo.WALL_LO, geo.WALL_HI
        for a, b in (((lo, hi), (lo, lo)), ((lo, lo), (hi, lo)), ((hi, lo), (hi, hi)), ((lo, hi), (hi, hi))):
            space.add(pymunk.Segment(space.static_body, a, b, geo.WALL_RADIUS))

        # Kinematic pusher: moved only by the velocity we set, immune to contact forces.
        agent = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        agent_shape = pymunk.Circle(agent, geo.AGENT_RADIUS)
        agent.position = (256.0, 400.0)

        # Mass and moment are given to the body directly and the shapes stay massless (as in
        # the reference), so pymunk does not recompute them from the shapes. Shape friction is
        # left at pymunk's default 0: every contact is frictionless (pymunk multiplies the two
        # shapes' frictions). The reference's ``body.friction = 1`` sets an unused Python
        # attribute and has no effect; we do not copy it.
        block = pymunk.Body(geo.T_MASS, geo.T_MOMENT)
        parts = [pymunk.Poly(block, [tuple(v) for v in verts])
                 for verts in (geo.CROSSBAR_LOCAL, geo.STEM_LOCAL)]
        block.center_of_gravity = geo.T_COG_LOCAL
        block.position = (256.0, 300.0)
        block.angle = 0.0
        space.add(agent, agent_shape, block, *parts)

        self._space, self._agent, self._block = space, agent, block
        self._dynamic_shapes = (agent_shape, *parts)

    # ----------------------------------------------------------------------------------------
    # State access (used by planners for cheap look-ahead in a scratch env)
    # ----------------------------------------------------------------------------------------
    def get_state(self) -> np.ndarray:
        """(7,) float64 [agent_x, agent_y, block_x, block_y, block_angle (unwrapped), agent_vx, agent_vy]."""
        ax, ay = self._agent.position
        bx, by = self._block.position
        vx, vy = self._agent.velocity
        return np.array([ax, ay, bx, by, self._block.angle, vx, vy], dtype=np.float64)

    def set_state(self, state) -> None:
        """Copy a simulator state exactly: (5,) [ax, ay, bx, by, angle] or (7,) with the agent's
        velocity (zero if absent).

        The angle is set BEFORE the position, so the block lands exactly at (bx, by, angle)
        (pymunk rotates bodies about their centre of gravity; compare the legacy order in
        ``reset``). The block's own velocity is zeroed and pymunk's cached contact impulses are
        cleared. Does not touch the step counter or the episode's reward bookkeeping.

        NOT a full copy (measured): Chipmunk keeps per-body BIAS velocities from the last
        substep's penetration correction (used by the next substep's position update, cleared
        after it, not reachable through pymunk) and the block's velocity from the last contact.
        After a substep with overlap (a reset whose pusher starts inside the T or whose T starts
        in a wall, or any push) ``set_state(s); step(a)`` can therefore differ from a fresh env
        placed at s by a fraction of a unit, which an open-loop replay through contacts grows to
        tens of px (0-21 px measured for expert episodes). Nothing depends on memory layout or
        on other envs in the process: the same history gives the same result. For an exact
        replay, reset a fresh env the way the episode was reset (same ``seed`` or
        ``reset_to_state``) and apply the recorded actions (``coursekit.teleop.replay``).
        """
        s = self.check_state(state)
        space = self._space
        # Removing and re-adding the shapes drops their cached contacts (about 10 us).
        space.remove(*self._dynamic_shapes)
        self._agent.position = (s[0], s[1])
        self._agent.velocity = (s[5], s[6]) if s.shape[0] == 7 else (0.0, 0.0)
        self._block.velocity = (0.0, 0.0)
        self._block.angular_velocity = 0.0
        self._block.angle = s[4]
        self._block.position = (s[2], s[3])
        space.add(*self._dynamic_shapes)

    @staticmethod
    def check_state(state) -> np.ndarray:
        """``state`` as a finite float64 (5,) [ax, ay, bx, by, angle] or (7,) (+ agent vx, vy); else ValueError."""
        try:
            s = np.asarray(state, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise ValueError(f"state must be numeric with shape (5,) or (7,), got {state!r}") from err
        if s.shape not in ((5,), (7,)):
            raise ValueError(f"state must have shape (5,) [ax, ay, bx, by, angle] or (7,) (+ agent vx, vy), "
                             f"got shape {s.shape}: {state!r}")
        if not np.all(np.isfinite(s)):
            raise ValueError(f"state must be finite, got {s.tolist()!r}")
        return s

    def block_pose(self) -> np.ndarray:
        """(3,) [x, y, angle (unwrapped)] of the block's body origin."""
        bx, by = self._block.position
        return np.array([bx, by, self._block.angle], dtype=np.float64)

    # ----------------------------------------------------------------------------------------
    # Gymnasium API
    # ----------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode from the seeded reference distribution or ``options["reset_to_state"]``.

        The seeded draw reproduces the reference exactly: ``np.random.RandomState(seed)`` gives
        agent x, y ~ randint(50, 450), block x, y ~ randint(100, 400), angle ~ randn() 2 pi - pi
        (Gaussian, not uniform). Without a seed the draw's seed comes from ``self.np_random``.

        LEGACY ORDER (kept for comparability with the reference data and evaluation): the block
        position is set while the body is at angle 0, THEN the angle; pymunk rotates about the
        centre of gravity c = (0, 45), so the block's origin lands at
        (bx, by) + c - R(angle) c, not at (bx, by) (``pusht_geometry.legacy_pose``). The same
        applies to ``reset_to_state``. Then one physics substep runs (as in the reference) to
        resolve any initial overlap. Use ``set_state`` for an exact placement.
        """
        options = check_reset_args(seed, options, RESET_OPTIONS, "PushTEnv")
        start = None  # checked before anything changes: a refused reset leaves the episode as it was
        if options.get("reset_to_state") is not None:
            start = check_start(finite_array(options["reset_to_state"], (5,), "options['reset_to_state']",
                                             "[ax, ay, bx, by, angle]"))
        super().reset(seed=seed)
        if start is None:
            draw_seed = seed if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
            rs = np.random.RandomState(seed=draw_seed)
            start = np.array([rs.randint(50, 450), rs.randint(50, 450),
                              rs.randint(100, 400), rs.randint(100, 400),
                              rs.randn() * 2 * np.pi - np.pi], dtype=np.float64)
        self._build_space()
        self._agent.position = (float(start[0]), float(start[1]))
        self._block.position = (float(start[2]), float(start[3]))  # legacy: position first...
        self._block.angle = float(start[4])  # ...then angle: rotates about the CoG (shifts the T)
        self._space.step(self.dt)  # the reference's "run physics to take effect"
        self._steps = 0
        self._last_action = None
        cov = self._scorer(self.block_pose())
        return self._observation(), self._info(cov)

    def step(self, action):
        """Apply one absolute pusher target (2,) for 10 substeps; returns the gymnasium 5-tuple."""
        self.physics_step(action)
        self._steps += 1
        cov = self._scorer(self.block_pose())
        reward = geo.reward_from_coverage(cov)
        terminated = cov > geo.SUCCESS_THRESHOLD
        truncated = self._steps >= self.max_episode_steps
        return self._observation(), reward, bool(terminated), bool(truncated), self._info(cov)

    def physics_step(self, action) -> None:
        """Only the physics of one env step (no observation, reward or step count): the cheap
        primitive for planners' look-ahead in a scratch env (tens of microseconds)."""
        ax, ay = self.check_action(action)
        self._last_action = np.array([ax, ay])
        agent, space, dt = self._agent, self._space, self.dt
        for _ in range(self.n_substeps):
            px, py = agent.position
            vx, vy = agent.velocity
            # PD tracking, written exactly as the reference: v += (k_p (a - x) + k_v (0 - v)) dt.
            agent.velocity = (vx + (K_P * (ax - px) + K_V * (0.0 - vx)) * dt,
                              vy + (K_P * (ay - py) + K_V * (0.0 - vy)) * dt)
            space.step(dt)

    @staticmethod
    def check_action(action) -> tuple[float, float]:
        """A finite pusher target (2,) as (x, y) clipped to the world [0, 512]; else ValueError."""
        a = finite_array(action, (2,), "action", "= pusher target (x, y)")
        x, y = float(a[0]), float(a[1])
        # Documented departure: targets outside the world are clipped to [0, 512].
        w = geo.WORLD_SIZE
        return min(max(x, 0.0), w), min(max(y, 0.0), w)

    # ----------------------------------------------------------------------------------------
    # Observations, info, rendering
    # ----------------------------------------------------------------------------------------
    def _state5(self) -> np.ndarray:
        """(5,) [ax, ay, bx, by, angle mod 2 pi] (the "state" observation)."""
        ax, ay = self._agent.position
        bx, by = self._block.position
        return np.array([ax, ay, bx, by, self._block.angle % (2 * math.pi)], dtype=np.float64)

    def _observation(self):
        if self.obs_type == "state":
            return self._state5()
        if self.obs_type == "keypoints":
            ax, ay = self._agent.position
            kp = geo.block_keypoints(self.block_pose()).reshape(-1)  # (16,)
            return np.concatenate([[ax, ay], kp])  # (18,)
        pixels = self._obs_renderer.render(self._state5())
        if self.obs_type == "pixels":
            return pixels
        return {"pixels": pixels, "agent_pos": np.array(self._agent.position, dtype=np.float64)}

    def _info(self, cov: float) -> dict:
        return {"coverage": float(cov), "is_success": bool(cov > geo.SUCCESS_THRESHOLD),
                "block_pose": self.block_pose(),
                "agent_pos": np.array(self._agent.position, dtype=np.float64)}

    def render(self):
        """(H, W, 3) uint8 view at ``render_size`` (with the latest action target marked), or
        None when ``render_mode`` is None."""
        if self.render_mode is None:
            return None
        if self._view_renderer is None:
            from coursekit.envs.pusht_render import PushTRenderer

            self._view_renderer = PushTRenderer(self.render_size)
        return self._view_renderer.render(self._state5(), target=self._last_action)
