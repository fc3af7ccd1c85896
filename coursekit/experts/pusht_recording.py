"""What the PushT expert records: one episode's rows (state before the action, action, coverage, phase).

:class:`Recorder` steps the real env for :class:`~coursekit.experts.pusht_planner.PushTExpert`
and decides when an episode is done; :class:`EpisodeRecord` is the finished episode.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from coursekit.envs import pusht_geometry as geo

# Phase of each recorded step.
SETTLE, TRAVEL, PUSH, REST = 0, 1, 2, 3
PHASE_NAMES = ("settle", "travel", "push", "rest")


@dataclass
class EpisodeRecord:
    """One expert episode. Row t holds the state BEFORE action t.

    states: (T, 5) [agent_x, agent_y, block_x, block_y, block_angle (unwrapped)].
    actions: (T, 2) pusher targets.
    coverage: (T,) coverage of the row's state.
    phases: (T,) int8 SETTLE / TRAVEL / PUSH / REST.
    success_step: number of actions after which coverage first passed 0.95 (None: failed);
        the env's ``terminated``, and what success rates and step counts measure.
    finish_step: number of actions after which the expert stopped pushing (coverage above 0.95
        and staying above ``final_coverage`` at rest); usually ``success_step``, later when the
        first crossing was only in passing. The rest steps follow it.
    route_choices: one dict per coin toss {"step", "side", "taken", "lengths": [cw, ccw]}.
    travel_bumps: travel legs that still touched the block after slowing down (expected 0).
    """

    states: np.ndarray
    actions: np.ndarray
    coverage: np.ndarray
    phases: np.ndarray
    success_step: int | None
    finish_step: int | None
    route_choices: list[dict] = field(default_factory=list)
    travel_bumps: int = 0


class Recorder:
    """Steps the real env and records (state before the action, action, coverage, phase).

    The episode is done once the coverage has passed 0.95 at a moment when ``rests_well(state)``
    says it will stay in place at rest (or after ``max_steps``). ``noise()`` (optional, (2,) px)
    is added to the executed target only; the recorded action stays the expert's.
    """

    def __init__(self, env, coverage: float, max_steps: int, rests_well, noise=None):
        self.env, self.max_steps, self.rests_well, self.noise = env, max_steps, rests_well, noise
        self.coverage = float(coverage)
        self.rows: list[tuple[np.ndarray, np.ndarray, float, int]] = []
        self.success_step: int | None = None
        self.finish_step: int | None = None

    @property
    def n_steps(self) -> int:
        return len(self.rows)

    @property
    def done(self) -> bool:
        return self.finish_step is not None or self.n_steps >= self.max_steps

    def step(self, target: np.ndarray, phase: int, force: bool = False) -> None:
        if self.done and not force:
            return
        state = self.env.get_state()[:5]
        action = np.clip(np.asarray(target, dtype=np.float64), 0.0, geo.WORLD_SIZE)
        self.rows.append((state, action, self.coverage, phase))
        executed = action if self.noise is None else np.clip(action + self.noise(), 0.0, geo.WORLD_SIZE)
        _, _, _, _, info = self.env.step(executed)
        self.coverage = float(info["coverage"])
        if info["is_success"]:
            if self.success_step is None:
                self.success_step = self.n_steps
            if self.finish_step is None and phase != REST and self.rests_well(self.env.get_state()):
                self.finish_step = self.n_steps

    def follow(self, targets: np.ndarray, phase: int) -> None:
        for target in targets:
            self.step(target, phase)

    def record(self, choices: list[dict], bumps: int) -> EpisodeRecord:
        if not self.rows:  # nothing to do (e.g. max_steps reached while settling)
            return EpisodeRecord(np.empty((0, 5)), np.empty((0, 2)), np.empty(0), np.empty(0, np.int8),
                                 self.success_step, self.finish_step, choices, bumps)
        states, actions, coverage, phases = zip(*self.rows)
        return EpisodeRecord(states=np.stack(states), actions=np.stack(actions),
                             coverage=np.asarray(coverage), phases=np.asarray(phases, dtype=np.int8),
                             success_step=self.success_step, finish_step=self.finish_step,
                             route_choices=choices, travel_bumps=bumps)
