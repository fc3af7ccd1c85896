"""A scripted PushT expert: plan a push, walk round the T to it, push, repeat, then rest.

The paper's 206 human demonstrations cannot be downloaded, so the course makes its own with
this planner (the ideas are in ``shared/reference/pusht.md``, "A scripted expert that works";
plain sampling MPC on raw pusher targets solves only about 10 % of resets). One episode:

1. settle    if the reset left the pusher overlapping the T (or the T in a wall), hold still
             until the physics has pushed them apart;
2. plan      rank every candidate push (contact x depth, ``pusht_push_model``) by the drop in
             log pose error per env step it costs, travel included; replay the best few in a
             scratch copy of the simulator and keep the best real one;
3. travel    back off, then go straight to the push's approach point if the line is clear,
             else round the T (``pusht_routes``); when clockwise and anticlockwise are about
             as long, a seeded coin picks the side (the demonstrations' built-in multimodality);
             the route is replayed first and slowed until it does not brush the block;
4. push      re-check the push from the real state, push in along the contact normal, hold,
             back off; go to 2 until the coverage passes 0.95;
5. rest      a few steps with the target on the pusher's own position, so that learned
             policies see when to stop (see the lessons in ``diffusion_policy.md``).

Targets move at most ``travel_speed`` px per 10 Hz step and brake before corners and at the
end, the way a hand would. Everything is deterministic given the reset seed and coin seed.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from coursekit.envs import pusht_geometry as geo
from coursekit.experts.pusht_clearance import local_to_world, world_to_local
from coursekit.experts.pusht_push_model import candidate_contacts, pose_error, predict_pushes
from coursekit.experts.pusht_routes import ANTICLOCKWISE, CLOCKWISE, STRAIGHT, RoutePlanner, speed_profile_targets

EXPERT_NAME = "coursekit.experts.pusht_planner"
EXPERT_VERSION = "1"
COIN_STREAM = 0xC01
"""Mixed into the coin's seed so the coin never shares a random stream with the env's reset."""

# Phase of each recorded step (stored per step by ``run_episode``).
SETTLE, TRAVEL, PUSH, REST = 0, 1, 2, 3
PHASE_NAMES = ("settle", "travel", "push", "rest")


@dataclass
class ExpertConfig:
    """Settings of the scripted PushT expert (pixels are world units, steps are 10 Hz env steps)."""

    max_steps: int = 300
    """Give up after this many env steps (the reference evaluation episode length)."""
    travel_speed: float = 35.0
    """Speed limit of the pusher's target while travelling (px per step)."""
    travel_accel: float = 12.0
    """How fast the target may speed up or brake while travelling (px per step^2)."""
    turn_speed: float = 15.0
    """Target speed at a right-angle turn of a route (the lagging pusher cuts corners)."""
    travel_margin: float = 6.0
    """Clearance kept between the pusher's edge and the T while travelling (px)."""
    approach_gap: float = 9.0
    """Gap between the pusher's edge and the contact at the end of a route (px)."""
    standoff_gap: float = 3.0
    """Gap at which the pusher stops short of the contact before pushing in (px)."""
    push_speed: float = 14.0
    """Fastest target speed while pushing (px per step); shorter pushes go slower."""
    push_depths: tuple[float, ...] = (3.0, 6.0, 11.0, 18.0, 28.0, 42.0, 60.0)
    """How far past first touch a push may drive the pusher (px); candidates try each."""
    contact_spacing: float = 10.0
    """Spacing of candidate contacts along the T's edges (px)."""
    corner_directions: int = 3
    """Push directions tried strictly inside each convex corner's 90 degree range."""
    n_verify: int = 6
    """Candidate pushes replayed in the scratch simulator before choosing one."""
    hold_steps: int = 1
    """Steps the push target holds still at the end of a push (the pusher catches up)."""
    route_tolerance: float = 0.35
    """Clockwise and anticlockwise routes whose lengths differ by less than this fraction of the
    shorter one count as a real two-way choice: a seeded coin picks the side."""
    rest_steps: int = 5
    """Steps at rest (target = pusher position) recorded after success."""
    max_settle_steps: int = 20
    """At most this many steps waiting for an overlapping reset to settle."""

    def __post_init__(self) -> None:
        for name in ("travel_speed", "travel_accel", "turn_speed", "push_speed", "contact_spacing"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("max_steps", "n_verify"):
            if not getattr(self, name) >= 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)!r}")
        for name in ("hold_steps", "rest_steps", "max_settle_steps", "corner_directions"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 <= self.standoff_gap < self.approach_gap:
            raise ValueError(f"need 0 <= standoff_gap < approach_gap, got {self.standoff_gap!r}, {self.approach_gap!r}")
        if self.travel_margin <= 0 or self.travel_margin > self.approach_gap:
            raise ValueError(f"need 0 < travel_margin <= approach_gap, got {self.travel_margin!r} (approach_gap {self.approach_gap!r})")
        if self.turn_speed > self.travel_speed:
            raise ValueError(f"turn_speed {self.turn_speed!r} exceeds travel_speed {self.travel_speed!r}")
        if not self.push_depths or min(self.push_depths) <= 0:
            raise ValueError(f"push_depths must be a non-empty tuple of positive depths, got {self.push_depths!r}")
        if self.route_tolerance < 0:
            raise ValueError(f"route_tolerance must be >= 0, got {self.route_tolerance!r}")
        self.push_depths = tuple(float(d) for d in self.push_depths)


@dataclass
class EpisodeRecord:
    """One expert episode. Row t holds the state BEFORE action t.

    states: (T, 5) [agent_x, agent_y, block_x, block_y, block_angle (unwrapped)].
    actions: (T, 2) pusher targets.
    coverage: (T,) coverage of the row's state.
    phases: (T,) int8 SETTLE / TRAVEL / PUSH / REST.
    success_step: number of actions after which the coverage first passed 0.95 (None: failed).
    route_choices: one dict per coin toss {"step", "side", "lengths": [cw, ccw]}.
    travel_bumps: travel legs that still touched the block after slowing down (should be 0).
    """

    states: np.ndarray
    actions: np.ndarray
    coverage: np.ndarray
    phases: np.ndarray
    success_step: int | None
    route_choices: list[dict] = field(default_factory=list)
    travel_bumps: int = 0


@dataclass
class _Push:
    """A push in world coordinates: where to approach, and the targets that execute it."""

    contact: int
    depth: float
    approach: np.ndarray  # (2,) end of the route, ``approach_gap`` from the contact
    standoff: np.ndarray  # (2,) where the push starts, ``standoff_gap`` from the contact
    targets: np.ndarray  # (T, 2) push in, hold, back off
    score: float = -np.inf


class PushTExpert:
    """The planner. ``run_episode(env, seed)`` plays one episode and returns its record.

    It owns a scratch ``PushTEnv`` for look-ahead: copy the real state in with ``set_state``
    (angle before position), step it, read the block back (tens of microseconds a step).
    """

    def __init__(self, config: ExpertConfig | None = None):
        from coursekit.envs.pusht import PushTEnv

        self.config = config or ExpertConfig()
        cfg = self.config
        self.radius = geo.AGENT_RADIUS
        self.contacts = candidate_contacts(cfg.contact_spacing, cfg.corner_directions, self.radius)
        self.routes = RoutePlanner(clearance=self.radius + cfg.travel_margin,
                                   waypoint_clearance=self.radius + cfg.approach_gap)
        self._approach_local = self.contacts.standoff(cfg.approach_gap, self.radius)  # (M, 2)
        self._standoff_local = self.contacts.standoff(cfg.standoff_gap, self.radius)
        self._scratch = PushTEnv(obs_type="state")
        self._scratch.reset(seed=0)
        self._coverage = geo.CoverageScorer(geo.GOAL_POSE)

    # ----------------------------------------------------------------------------------------
    # Look-ahead in the scratch simulator
    # ----------------------------------------------------------------------------------------
    def _simulate(self, state: np.ndarray, targets: np.ndarray, stop_on_success: bool = False):
        """Replay ``targets`` (T, 2) from ``state`` (5,) or (7,) in the scratch env.

        Returns (final state (7,), index of the first step whose coverage passes 0.95 or None).
        Coverage (a polygon intersection) is only computed once the pose is near the goal.
        """
        sim = self._scratch
        sim.set_state(state)
        success = None
        for t, target in enumerate(targets):
            sim.physics_step(target)
            if success is None:
                pose = sim.block_pose()
                if pose_error(pose) < 25.0 and self._coverage(pose) > geo.SUCCESS_THRESHOLD:
                    success = t
                    if stop_on_success:
                        break
        return sim.get_state(), success

    def _rests_successfully(self, state: np.ndarray) -> bool:
        """Whether coverage stays above 0.95 after ``rest_steps`` of targets at the pusher."""
        sim = self._scratch
        sim.set_state(state)
        for _ in range(self.config.rest_steps):
            sim.physics_step(sim.get_state()[:2])
        return self._coverage(sim.block_pose()) > geo.SUCCESS_THRESHOLD

    # ----------------------------------------------------------------------------------------
    # Pushes
    # ----------------------------------------------------------------------------------------
    def _push_targets(self, standoff: np.ndarray, normal: np.ndarray, depth: float) -> np.ndarray:
        """(T, 2) targets: from the standoff point in along ``normal`` by gap + depth (faster
        for longer pushes), hold, then back off two steps to the approach distance."""
        cfg = self.config
        dist = cfg.standoff_gap + depth
        speed = float(np.clip(0.4 * dist, 3.0, cfg.push_speed))
        n_in = max(1, math.ceil(dist / speed))
        along = dist * np.arange(1, n_in + 1) / n_in
        back = dist - cfg.approach_gap * np.array([0.5, 1.0])
        steps = np.concatenate([along, np.full(cfg.hold_steps, dist), back])  # (T,)
        return standoff + steps[:, None] * normal  # (T, 2)

    def _world_push(self, pose: np.ndarray, contact: int, depth: float) -> _Push:
        normal = local_to_world(self.contacts.normal[contact], (0.0, 0.0, pose[2]))  # rotate only
        standoff = local_to_world(self._standoff_local[contact], pose)
        approach = local_to_world(self._approach_local[contact], pose)
        return _Push(contact, depth, approach, standoff, self._push_targets(standoff, normal, depth))

    def _score(self, err0: float, err1: float, success: int | None, steps: float) -> float:
        """Drop in log pose error per step; reaching success counts as reaching 0.5 px."""
        if success is not None:
            err1 = min(err1, 0.5)
        return (math.log(err0) - math.log(max(err1, 1e-3))) / max(steps, 1.0)

    def _travel_steps(self, length: np.ndarray) -> np.ndarray:
        """Rough step count of a route of ``length`` px (cruise plus speeding up and braking)."""
        cfg = self.config
        return np.where(length < 1.0, 0.0, length / cfg.travel_speed + cfg.travel_speed / cfg.travel_accel)

    def plan_push(self, state: np.ndarray) -> _Push | None:
        """Best push from ``state`` (7,): model ranking, then scratch-simulator check."""
        cfg = self.config
        pose = state[2:5]
        err0 = float(pose_error(pose))
        depths = np.asarray(cfg.push_depths)
        predicted = predict_pushes(pose, self.contacts, depths)  # (M, D, 3)
        gain = math.log(err0) - np.log(np.maximum(pose_error(predicted), 1e-3))  # (M, D)
        start_local = world_to_local(state[:2], pose)
        lengths = self.routes.lengths(pose, start_local, self._approach_local).min(axis=0)  # (M,)
        approach_w = local_to_world(self._approach_local, pose)
        in_arena = np.all((approach_w >= 0) & (approach_w <= geo.WORLD_SIZE), axis=1)
        reachable = np.isfinite(lengths) & in_arena  # (M,)
        n_push = np.array([len(self._push_targets(np.zeros(2), np.zeros(2), d)) for d in depths])  # (D,)
        travel = self._travel_steps(np.where(reachable, lengths, 0.0))  # (M,)
        score = gain / (travel[:, None] + n_push[None, :])  # (M, D)
        score[~reachable] = -np.inf
        order = np.argsort(-score, axis=None)[: cfg.n_verify]
        best = None
        for flat in order:
            m, d = np.unravel_index(flat, score.shape)
            if not np.isfinite(score[m, d]):
                break
            push = self._world_push(pose, int(m), float(depths[d]))
            start = np.concatenate([push.standoff, pose])  # pusher at rest at the standoff
            end, success = self._simulate(start, push.targets)
            if success is not None and not self._rests_successfully(end):
                success = None
            steps = travel[m] + (len(push.targets) if success is None else success + 1)
            push.score = self._score(err0, float(pose_error(end[2:5])), success, steps)
            if best is None or push.score > best.score:
                best = push
        return best

    def recheck_push(self, state: np.ndarray, push: _Push) -> _Push | None:
        """Re-plan the depth of ``push`` from the real ``state`` (7,) after travelling; None if
        no depth improves the pose any more."""
        pose = state[2:5]
        err0 = float(pose_error(pose))
        best = None
        for depth in self.config.push_depths:
            cand = self._world_push(pose, push.contact, depth)
            end, success = self._simulate(state, cand.targets)
            if success is not None and not self._rests_successfully(end):
                success = None
            steps = len(cand.targets) if success is None else success + 1
            cand.score = self._score(err0, float(pose_error(end[2:5])), success, steps)
            if cand.score > 0 and (best is None or cand.score > best.score):
                best = cand
        return best

    # ----------------------------------------------------------------------------------------
    # Travel
    # ----------------------------------------------------------------------------------------
    def _choose_side(self, state: np.ndarray, push: _Push, rng: np.random.Generator, step: int,
                     choices: list[dict]) -> list[str]:
        """Sides to try, preferred first. A coin toss (recorded in ``choices``) decides when
        clockwise and anticlockwise are about equally long."""
        pose = state[2:5]
        start_local = world_to_local(state[:2], pose)
        straight, cw, ccw = self.routes.lengths(pose, start_local, self._approach_local[push.contact][None])[:, 0]
        if np.isfinite(straight):
            return [STRAIGHT]
        if np.isfinite(cw) and np.isfinite(ccw):
            if abs(cw - ccw) <= self.config.route_tolerance * min(cw, ccw):
                side = CLOCKWISE if rng.random() < 0.5 else ANTICLOCKWISE
                choices.append({"step": step, "side": side, "lengths": [float(cw), float(ccw)]})
                return [side, ANTICLOCKWISE if side == CLOCKWISE else CLOCKWISE]
            return [CLOCKWISE, ANTICLOCKWISE] if cw < ccw else [ANTICLOCKWISE, CLOCKWISE]
        return [s for s, length in ((CLOCKWISE, cw), (ANTICLOCKWISE, ccw)) if np.isfinite(length)]

    def plan_travel(self, state: np.ndarray, push: _Push, sides: list[str]) -> tuple[np.ndarray, str, bool]:
        """Targets (T, 2) from the pusher to ``push.standoff`` along the first side whose replay
        leaves the block untouched (slowing down up to twice); returns (targets, side, touched)."""
        cfg = self.config
        pose = state[2:5]
        start_local = world_to_local(state[:2], pose)
        fallback = None
        for side in sides:
            route = self.routes.route(pose, start_local, self._approach_local[push.contact], side)
            points = np.concatenate([route.points, push.standoff[None]])  # (K+1, 2)
            for slow in (1.0, 0.6, 0.35):
                targets = speed_profile_targets(points, cfg.travel_speed * slow, cfg.travel_accel * slow,
                                                cfg.turn_speed * slow)
                end, _ = self._simulate(state, targets)
                if np.abs(end[2:5] - pose).max() < 1e-6:
                    return targets, side, False
                fallback = (targets, side) if fallback is None else fallback
        return fallback[0], fallback[1], True

    # ----------------------------------------------------------------------------------------
    # One episode
    # ----------------------------------------------------------------------------------------
    def run_episode(self, env, seed: int | None = None, coin_seed: int | None = None,
                    reset_state=None) -> EpisodeRecord:
        """Reset ``env`` (a ``PushTEnv``) with ``seed`` (or to ``reset_state`` (5,)) and solve it.

        ``coin_seed`` (default: ``seed``) seeds the coin that picks between equally good sides.
        """
        cfg = self.config
        options = None if reset_state is None else {"reset_to_state": np.asarray(reset_state, dtype=np.float64)}
        _, info = env.reset(seed=seed, options=options)
        coin = coin_seed if coin_seed is not None else (seed if seed is not None else 0)
        rng = np.random.default_rng([COIN_STREAM, int(coin)])
        ep = _Recorder(env, info["coverage"], cfg.max_steps)
        # 1. settle: an overlapping reset is pushed apart by the physics over a few steps.
        for _ in range(cfg.max_settle_steps):
            state = env.get_state()
            end, _ = self._simulate(state, state[None, :2])
            if np.abs(end[2:5] - state[2:5]).max() < 1e-3:
                break
            ep.step(state[:2], SETTLE)
        choices: list[dict] = []
        bumps = 0
        while not ep.done:
            state = env.get_state()
            push = self.plan_push(state)  # 2. plan
            if push is None:
                break
            # 3. travel (skipped when the pusher already stands at the standoff point)
            if np.linalg.norm(state[:2] - push.standoff) > 1.0:
                n_before = len(choices)
                sides = self._choose_side(state, push, rng, ep.n_steps, choices)
                if not sides:
                    break
                targets, side, touched = self.plan_travel(state, push, sides)
                if len(choices) > n_before:
                    choices[-1]["taken"] = side
                bumps += int(touched)
                for target in targets:
                    ep.step(target, TRAVEL)
                    if ep.done:
                        break
                if ep.done:
                    break
                push = self.recheck_push(env.get_state(), push)
                if push is None:
                    continue
            for target in push.targets:  # 4. push
                ep.step(target, PUSH)
                if ep.done:
                    break
        if ep.success_step is not None:  # 5. rest
            for _ in range(cfg.rest_steps):
                ep.step(env.get_state()[:2], REST, force=True)
        return ep.record(choices, bumps)


class _Recorder:
    """Steps the real env and records (state before action, action, coverage, phase)."""

    def __init__(self, env, coverage: float, max_steps: int):
        self.env, self.max_steps = env, max_steps
        self.coverage = float(coverage)
        self.rows: list[tuple[np.ndarray, np.ndarray, float, int]] = []
        self.success_step: int | None = None

    @property
    def n_steps(self) -> int:
        return len(self.rows)

    @property
    def done(self) -> bool:
        return self.success_step is not None or self.n_steps >= self.max_steps

    def step(self, target: np.ndarray, phase: int, force: bool = False) -> None:
        if self.done and not force:
            return
        state = self.env.get_state()[:5]
        action = np.clip(np.asarray(target, dtype=np.float64), 0.0, geo.WORLD_SIZE)
        self.rows.append((state, action, self.coverage, phase))
        _, _, _, _, info = self.env.step(action)
        self.coverage = float(info["coverage"])
        if self.success_step is None and info["is_success"]:
            self.success_step = self.n_steps

    def record(self, choices: list[dict], bumps: int) -> EpisodeRecord:
        states, actions, coverage, phases = zip(*self.rows)
        return EpisodeRecord(states=np.stack(states), actions=np.stack(actions),
                             coverage=np.asarray(coverage), phases=np.asarray(phases, dtype=np.int8),
                             success_step=self.success_step, route_choices=choices, travel_bumps=bumps)
