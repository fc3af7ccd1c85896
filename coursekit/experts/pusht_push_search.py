"""Choosing the next push: rank every candidate with the push model, check the best few in a
scratch copy of the simulator, keep the best real one.

A candidate is a contact on the T (``pusht_push_model.candidate_contacts``) and a depth. Its
score is the drop in log pose error per env step it costs, the travel to reach it included:
a log, so that the last few pixels count as much as the first hundred, and per step, so that
a short push next to the pusher can beat a better one round the other side.

The scratch simulator makes the check exact: ``set_state`` copies the real state in (angle
before position), ``physics_step`` replays the push's targets, and the block ends where the
real one will (the physics is deterministic). One step costs tens of microseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht_geometry import local_to_world, world_to_local
from coursekit.experts.pusht_config import ExpertConfig
from coursekit.experts.pusht_person import Picker
from coursekit.experts.pusht_push_model import candidate_contacts, pose_error, predict_pushes
from coursekit.experts.pusht_routes import RoutePlanner


@dataclass
class Push:
    """One push in world coordinates.

    contact: index into the candidate contacts; depth: px past first touch.
    approach: (2,) end of the route to it (``approach_gap`` from the contact).
    standoff: (2,) where pushing starts (``standoff_gap`` from the contact).
    push_in: (T, 2) targets that push in and hold; back_off: (2, 2) targets that retreat.
    score: drop in log pose error per step (travel included), as checked in the simulator.
    """

    contact: int
    depth: float
    approach: np.ndarray
    standoff: np.ndarray
    push_in: np.ndarray
    back_off: np.ndarray
    score: float = -math.inf

    @property
    def targets(self) -> np.ndarray:
        """(T + 2, 2) all targets: push in, hold, back off."""
        return np.concatenate([self.push_in, self.back_off])


class PushSearch:
    """Candidate pushes, the routes to them, and a scratch ``PushTEnv`` to check them in."""

    def __init__(self, config: ExpertConfig):
        from coursekit.envs.pusht import PushTEnv

        self.config = config
        radius = geo.AGENT_RADIUS
        self.contacts = candidate_contacts(config.contact_spacing, config.corner_directions, radius)
        self.routes = RoutePlanner(clearance=radius + config.travel_margin,
                                   waypoint_clearance=radius + config.approach_gap)
        self.approach_local = self.contacts.standoff(config.approach_gap, radius)  # (M, 2)
        self.standoff_local = self.contacts.standoff(config.standoff_gap, radius)  # (M, 2)
        self._sim = PushTEnv(obs_type="state")
        self._sim.reset(seed=0)
        self._coverage = geo.CoverageScorer(geo.GOAL_POSE)

    # ----------------------------------------------------------------------------------------
    # Look-ahead in the scratch simulator
    # ----------------------------------------------------------------------------------------
    def simulate(self, state: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, int | None]:
        """Replay ``targets`` (T, 2) from ``state`` (5,) or (7,) in the scratch env.

        Returns (final state (7,), index of the first step whose coverage passes 0.95, or None).
        """
        sim = self._sim
        sim.set_state(state)
        success = None
        for t, target in enumerate(targets):
            sim.physics_step(target)
            if success is None and self.is_success(sim.block_pose()):
                success = t
        return sim.get_state(), success

    def is_success(self, pose: np.ndarray, threshold: float = geo.SUCCESS_THRESHOLD) -> bool:
        """coverage > ``threshold`` (>= 0.95), with a cheap necessary test first (the polygon
        intersection costs more than a physics step). Sampling poses round the goal, none over
        0.95 was more than 3.1 px or 0.045 rad off; the box below leaves a wide margin."""
        gx, gy, ga = geo.GOAL_POSE
        turn = (pose[2] - ga + math.pi) % (2 * math.pi) - math.pi
        if abs(pose[0] - gx) > 8.0 or abs(pose[1] - gy) > 8.0 or abs(turn) > 0.12:
            return False
        return self._coverage(pose) > threshold

    def rests_successfully(self, state: np.ndarray) -> bool:
        """Whether the T at ``state`` (7,) still covers ``final_coverage`` of the goal after
        ``rest_steps`` steps with the target on the pusher (the pusher coasts to a stop)."""
        sim = self._sim
        sim.set_state(state)
        for _ in range(self.config.rest_steps):
            sim.physics_step(sim.get_state()[:2])
        return self.is_success(sim.block_pose(), self.config.final_coverage)

    def _evaluate(self, state: np.ndarray, push: Push, extra_steps: float) -> Push:
        """Score ``push`` replayed from ``state``. A push that reaches success counts only if the
        T still covers ``final_coverage`` of the goal after the rest steps (the pusher coasts on
        for a little), so that demonstrations end well inside the success region."""
        err0 = max(float(pose_error(state[2:5])), 1e-3)
        end, success = self.simulate(state, push.targets)
        if success is not None:
            at_success, _ = self.simulate(state, push.targets[: success + 1])
            if not self.rests_successfully(at_success):
                success = None
        err1 = 0.5 if success is not None else max(float(pose_error(end[2:5])), 1e-3)
        steps = extra_steps + (len(push.targets) if success is None else success + 1)
        push.score = (math.log(err0) - math.log(err1)) / max(steps, 1.0)
        return push

    # ----------------------------------------------------------------------------------------
    # Pushes
    # ----------------------------------------------------------------------------------------
    def _targets(self, start: np.ndarray, normal: np.ndarray, dist: float) -> tuple[np.ndarray, np.ndarray]:
        """Push-in targets (T, 2) from ``start`` along ``normal`` by ``dist`` (faster for longer
        pushes), then ``hold_steps`` in place; and two back-off targets (2, 2) to the approach
        distance."""
        cfg = self.config
        speed = float(np.clip(0.4 * dist, 3.0, cfg.push_speed))
        n_in = max(1, math.ceil(dist / speed))
        along = np.concatenate([dist * np.arange(1, n_in + 1) / n_in, np.full(cfg.hold_steps, dist)])
        back = dist - cfg.approach_gap * np.array([0.5, 1.0])
        return start + along[:, None] * normal, start + back[:, None] * normal

    def make_push(self, pose: np.ndarray, contact: int, depth: float) -> Push:
        """The push of ``contact`` by ``depth`` on a T at ``pose``, starting from the standoff."""
        normal = local_to_world(self.contacts.normal[contact], (0.0, 0.0, pose[2]))  # rotate only
        standoff = local_to_world(self.standoff_local[contact], pose)
        approach = local_to_world(self.approach_local[contact], pose)
        push_in, back_off = self._targets(standoff, normal, self.config.standoff_gap + depth)
        return Push(contact, depth, approach, standoff, push_in, back_off)

    def travel_steps(self, length: np.ndarray) -> np.ndarray:
        """Rough step count of a route of ``length`` px (cruise plus speeding up and braking)."""
        cfg = self.config
        return np.where(length < 1.0, 0.0, length / cfg.travel_speed + cfg.travel_speed / cfg.travel_accel)

    def plan(self, state: np.ndarray, extra_steps: float = 0.0, pick: Picker | None = None) -> Push | None:
        """Best push from ``state`` (7,): model ranking, then a check of the best ``n_verify``
        in the simulator (pusher at rest at the standoff). ``extra_steps`` are spent before
        travelling (a back-off still to come). ``pick`` (a person's choice, ``pusht_person``)
        chooses among the checked pushes instead of the best one."""
        cfg = self.config
        pose = state[2:5]
        depths = np.asarray(cfg.push_depths)
        predicted = predict_pushes(pose, self.contacts, depths)  # (M, D, 3)
        gain = math.log(max(float(pose_error(pose)), 1e-3)) - np.log(np.maximum(pose_error(predicted), 1e-3))  # (M, D)
        lengths = self.routes.lengths(pose, world_to_local(state[:2], pose), self.approach_local).min(axis=0)  # (M,)
        approach_w = local_to_world(self.approach_local, pose)
        reachable = np.isfinite(lengths) & np.all((approach_w >= 0) & (approach_w <= geo.WORLD_SIZE), axis=1)
        travel = extra_steps + self.travel_steps(np.where(reachable, lengths, 0.0))  # (M,)
        n_push = np.array([len(self.make_push(pose, 0, d).targets) for d in depths])  # (D,)
        score = np.where(reachable[:, None], gain / (travel[:, None] + n_push[None, :]), -np.inf)  # (M, D)
        best, checked = None, []
        for flat in np.argsort(-score, axis=None)[: cfg.n_verify]:
            m, d = np.unravel_index(flat, score.shape)
            if not np.isfinite(score[m, d]):
                break
            push = self.make_push(pose, int(m), float(depths[d]))
            at_standoff = np.concatenate([push.standoff, pose])  # pusher at rest there
            push = self._evaluate(at_standoff, push, travel[m])
            checked.append(push)
            if best is None or push.score > best.score:
                best = push
        return best if pick is None or not checked else pick(checked)

    def recheck(self, state: np.ndarray, push: Push) -> Push | None:
        """Re-choose the depth of ``push`` from the real ``state`` (7,) on arrival; None if no
        depth improves the pose any more."""
        depths = self.config.push_depths
        planned = depths.index(push.depth) if push.depth in depths else len(depths) // 2
        best = None
        for depth in depths[max(planned - 2, 0): planned + 3]:  # the planned depth and its neighbours
            cand = self._evaluate(state, self.make_push(state[2:5], push.contact, depth), 0.0)
            if cand.score > 0 and (best is None or cand.score > best.score):
                best = cand
        return best

    def continuation(self, state: np.ndarray, push: Push) -> Push | None:
        """Keep pushing the same contact without backing off (from the pusher's current target,
        along the contact's normal as the T now lies); None if no depth improves the pose."""
        pose = state[2:5]
        normal = local_to_world(self.contacts.normal[push.contact], (0.0, 0.0, pose[2]))
        best = None
        for depth in self.config.push_depths:
            push_in, back_off = self._targets(push.push_in[-1], normal, depth)
            cand = Push(push.contact, depth, push.approach, push.push_in[-1], push_in, back_off)
            cand = self._evaluate(state, cand, 0.0)
            if cand.score > 0 and (best is None or cand.score > best.score):
                best = cand
        return best
