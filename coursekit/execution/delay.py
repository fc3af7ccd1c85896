"""Executing action chunks while the next one is being computed: a control loop with inference delay d (§10.4).

Every executor of chapters 5 and 8 assumes the policy answers instantly. On a robot it does
not: a chunk that takes L seconds to compute at a control period of P seconds arrives
d = ceil(L / P) control steps after it was requested (P = 1 / a task's ``control_hz`` in
``coursekit.tasks``: PushT 10 Hz, the arm pair 50 Hz), and the robot must do something in the
meantime. This module SIMULATES that delay in step time: the chunk requested at step r is
computed at once (from the observations up to r) but handed to the robot only at step r + d. No threads, no clocks: the outcome depends only on
the seeds, so it is a measurement, not a race.

Glossary: To = n_obs_steps, Tp = horizon (ACT: k), Ta = n_action_steps, d = delay. A chunk
requested at step r holds, at index ``start + j`` (start = To - 1), its action for step r + j.
The first chunk of an episode is computed before the clock starts (the robot waits at rest for
it, as every deployment does), so it is ready at step 0 whatever d is. A chunk that runs out
before the next one arrives repeats its last action (a position-controlled robot holds its last
set-point). One inference runs at a time: a new request starts only after the last one arrived.

Strategies, all with ``reset(obs (B, ...))`` / ``act(obs (B, ...)) -> (B, Da)`` and built like
every executor, ``cls.from_spec(predict_chunk, spec, delay=d)``::

    step               r-1   r    r+1  ...  r+d-1   r+d  ...
    Synchronous        [...] hold hold ...  hold    a_0  a_1 ...   robot waits d steps, then the
                                                                   chunk from its first action
    AsyncChunking      old   old  old  ...  old     a_d  a_d+1 ... keep moving; switch on arrival,
                                                                   dropping the d stale actions
    DelayedEnsemble    average of every ARRIVED chunk covering the step (ACT's weights)
    RealTimeChunking   (coursekit.execution.rtc) as AsyncChunking, but the new chunk was generated
                       with a_0..a_d-1 frozen to the committed actions and the rest of the overlap
                       guided toward the old chunk, so the switch does not jump

With d = 0 the first two and RealTimeChunking are exactly
:class:`~coursekit.execution.receding.RecedingHorizon` and DelayedEnsemble is exactly
:class:`~coursekit.execution.ensembling.TemporalEnsemble` (tests/test_execution_delay.py).

``AsyncChunking.act`` is exercise "async_chunking" (11.1).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from coursekit.execution.receding import batch_size_of, stack_history, to_numpy

def delay_steps(latency_s: float, control_hz: float) -> int:
    """d = ceil(latency / control period): control steps that pass while one chunk is computed.

    ``control_hz`` is the task's rate (``coursekit.tasks.get_task(name).control_hz``).

    A latency of exactly k periods gives d = k (the chunk is ready at the k-th tick); a
    tolerance of 1e-9 periods keeps float noise (0.3 s at 10 Hz = 2.9999...) from adding a step.
    Deliberate: the RTC paper (Black et al. 2025), as we read it, writes d with a floor; rounding
    up is the conservative reading (a chunk arriving mid-period has missed that tick) and the one
    used throughout the course; both agree at whole periods.
    """
    if not (isinstance(latency_s, (int, float, np.floating)) and math.isfinite(latency_s) and latency_s >= 0):
        raise ValueError(f"latency_s must be a finite number of seconds >= 0, got {latency_s!r}")
    if not (isinstance(control_hz, (int, float, np.floating)) and math.isfinite(control_hz) and control_hz > 0):
        raise ValueError(f"control_hz must be a positive number, got {control_hz!r}")
    return max(0, math.ceil(float(latency_s) * float(control_hz) - 1e-9))


def _check_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


@dataclass
class Chunk:
    """A chunk in flight or in use: its actions from ``start`` on and the step it was requested at."""

    actions: Any
    """(B, L, Da) actions for steps request, request + 1, ... (L = Tp - start); numpy or torch."""
    request: int
    """Step r whose observation the chunk was computed from (index 0 of ``actions`` is for step r)."""
    arrival: int
    """Step the robot can first use it: r + d (r for the first chunk of an episode)."""
    index: int
    """0, 1, 2, ...: which request of the episode this is (for plots and tests)."""

    @property
    def length(self) -> int:
        return int(self.actions.shape[1])

    def action_at(self, t: int) -> Any:
        """The action for step t (B, Da); past the chunk's end its last action (hold)."""
        if t < self.request:
            raise ValueError(f"chunk requested at step {self.request} has no action for the earlier step {t}")
        return self.actions[:, min(t - self.request, self.length - 1)]


class DelayedExecutor:
    """Shared machinery: the observation history, the step clock and the delayed inference.

    Args:
        predict_chunk: (B, To, ...) history -> (B, Tp, Da) chunk in raw units.
        n_obs_steps: To.
        n_action_steps: Ta, actions executed per chunk when there is no delay.
        delay: d >= 0, control steps between a request and its arrival.
        start: index of the action for "now" in a chunk (default To - 1).

    Logs (reset each episode), for plots and tests: ``requests`` (steps at which inference
    started), ``switches`` (steps at which a new chunk took over) and ``trace``: per step the
    (chunk index, index into that chunk's actions) executed, (-1, -1) for a hold or an average.
    """

    def __init__(self, predict_chunk: Callable[[Any], Any], n_obs_steps: int = 2, n_action_steps: int = 8,
                 delay: int = 0, start: int | None = None) -> None:
        if not callable(predict_chunk):
            raise ValueError(f"predict_chunk must be callable (B, To, ...) -> (B, Tp, Da), got {predict_chunk!r}")
        self.predict_chunk = predict_chunk
        self.n_obs_steps = _check_int("n_obs_steps (To)", n_obs_steps, 1)
        self.n_action_steps = _check_int("n_action_steps (Ta)", n_action_steps, 1)
        self.delay = _check_int("delay (d)", delay, 0)
        self.start = self.n_obs_steps - 1 if start is None else _check_int("start", start, 0)
        self.history: list[Any] = []
        self.t = 0

    @classmethod
    def from_spec(cls, predict_chunk: Callable[[Any], Any], spec: Any, delay: int = 0, **kwargs: Any) -> DelayedExecutor:
        """Built like every executor: To and Ta (and m) from an :class:`~coursekit.execution.spec.ExecutionSpec`."""
        return cls(predict_chunk, n_obs_steps=int(spec.n_obs_steps), n_action_steps=int(spec.n_action_steps),
                   delay=delay, **kwargs)

    # ---- episode state -----------------------------------------------------------------
    def reset(self, obs: Any) -> None:
        """Start an episode: history = To copies of ``obs`` (B, ...); no chunk, clock at 0."""
        self.history = [obs] * self.n_obs_steps
        self.t = 0
        self.current: Chunk | None = None
        self.pending: Chunk | None = None
        self.next_request = 0
        self.last_action: Any = None
        self.requests: list[int] = []
        self.switches: list[int] = []
        self.trace: list[tuple[int, int]] = []

    def _observe(self, obs: Any) -> None:
        if not self.history:
            raise ValueError("act() called before reset(obs): call reset with the first observation")
        self.history = [*self.history[1:], obs]  # the newest To observations, oldest first

    # ---- delayed inference -------------------------------------------------------------
    def _compute(self) -> Any:
        """Run the predictor on the current history; check and return the chunk (B, Tp, Da)."""
        obs_history = stack_history(self.history)  # (B, To, ...)
        chunk = self.predict_chunk(obs_history)
        b = batch_size_of(obs_history)
        shape = tuple(getattr(chunk, "shape", ()))
        if len(shape) != 3 or shape[0] != b or shape[1] <= self.start:
            raise ValueError(f"predict_chunk returned shape {shape}; expected (B={b}, Tp > start={self.start}, Da)")
        return chunk

    def _request(self) -> None:
        """Start inference now (step t): the chunk becomes ``self.pending``, usable from step t + d."""
        chunk = self._compute()
        first = not self.requests
        self.pending = Chunk(chunk[:, self.start:], request=self.t, arrival=self.t if first else self.t + self.delay,
                             index=len(self.requests))
        self.requests.append(self.t)

    def _receive(self) -> bool:
        """If the pending chunk has arrived by step t, it becomes ``self.current``; True if it did."""
        if self.pending is not None and self.pending.arrival <= self.t:
            self.current, self.pending = self.pending, None
            self.switches.append(self.t)
            return True
        return False

    def _emit(self, action: Any, chunk_index: int = -1, action_index: int = -1) -> Any:
        self.trace.append((chunk_index, action_index))
        self.last_action = action
        self.t += 1
        return action

    def act(self, obs: Any) -> Any:  # pragma: no cover - every strategy overrides it
        raise NotImplementedError


class Synchronous(DelayedExecutor):
    """Receding horizon with a pause: after Ta actions the robot holds its last action for d steps.

    The chunk requested at the boundary is then executed from its first action (index start),
    as if no time had passed: the robot did not move while the policy was thinking. On PushT
    nothing else did either: the block has no momentum (``space.damping = 0`` in
    coursekit/envs/pusht.py, so it moves only while pushed) and the pause costs only time; on a
    dynamic task the world would move on meanwhile. d = 0 is exactly RecedingHorizon.
    """

    def reset(self, obs: Any) -> None:
        super().reset(obs)
        self.executed = 0  # actions of the current chunk executed so far

    def act(self, obs: Any) -> Any:
        self._observe(obs)
        if self.pending is None and (self.current is None or self.executed >= self.n_action_steps):
            self._request()  # the robot stops here until the chunk arrives
        if self._receive():
            self.executed = 0
        if self.pending is not None:  # still thinking: hold still
            return self._emit(self.last_action)
        i = min(self.executed, self.current.length - 1)
        self.executed += 1
        return self._emit(self.current.actions[:, i], self.current.index, i)


class AsyncChunking(DelayedExecutor):
    """Naive asynchronous execution: request the next chunk early, switch the moment it arrives.

    Requests happen every ``period = max(Ta, d)`` steps (the first at step 0), so each request
    arrives when the current chunk has run for Ta steps (or, if d > Ta, the instant the previous
    inference ends: one inference at a time). On arrival at step r + d the new chunk's first d
    actions, meant for steps r .. r + d - 1, are already in the past: execution starts at its
    action for step r + d. d = 0 is exactly RecedingHorizon.

    Why this is exercise 11.1: every strategy of the chapter, real-time chunking included, runs
    on this schedule, and the delay is nothing but this bookkeeping (which chunk, which index,
    from which observation); it is exact integer logic a hand-built chunk stream checks step by
    step. RTC's own step (its weights and guided update) is exercise 11.2, in
    :mod:`coursekit.execution.rtc`.
    """

    @property
    def period(self) -> int:
        """Steps between two requests: max(Ta, d)."""
        return max(self.n_action_steps, self.delay)

    def act(self, obs: Any) -> Any:
        """Push ``obs`` (B, ...) into the history and return the action for step t = ``self.t``, (B, Da).

        1. ``self._receive()``: if the pending chunk has arrived (arrival <= t) it becomes
           ``self.current`` (do this FIRST: the step a chunk arrives, the next may be requested).
        2. If nothing is pending and t >= ``self.next_request``: ``self._request()`` (inference
           from the newest observations; the chunk arrives at t + d, or at t for the episode's
           first request) and ``self.next_request = t + self.period``; then ``self._receive()``
           again (with d = 0, or at t = 0, the chunk is usable at once).
        3. The action is ``self.current.action_at(t)``: the current chunk's action for step t
           (index t - request, its last action past its end). Return ``self._emit(action,
           chunk_index, action_index)``, which logs the step and advances the clock.
        """
        self._observe(obs)
        t = self.t
        # BEGIN SOLUTION
        self._receive()
        if self.pending is None and t >= self.next_request:
            self._request()
            self.next_request = t + self.period
            self._receive()
        chunk = self.current
        i = min(t - chunk.request, chunk.length - 1)
        return self._emit(chunk.action_at(t), chunk.index, i)
        # END SOLUTION


class DelayedEnsemble(DelayedExecutor):
    """Temporal ensembling (ACT) when every chunk arrives d steps late.

    A new request starts every max(1, d) steps (one inference at a time: with d >= 1 the next
    one starts when the last one arrives). At step t the action averages every ARRIVED chunk
    covering t with ACT's weights w_i = exp(-m i), oldest first (i = 0 the oldest; reversed by
    ``newest_first``). When no chunk covers t the last action is held. d = 0 is exactly
    TemporalEnsemble (same arithmetic, step for step).
    """

    def __init__(self, predict_chunk: Callable[[Any], Any], n_obs_steps: int = 1, n_action_steps: int = 1,
                 delay: int = 0, start: int | None = None, ensemble_decay: float = 0.01, newest_first: bool = False) -> None:
        super().__init__(predict_chunk, n_obs_steps, n_action_steps, delay, start)
        if not (isinstance(ensemble_decay, (int, float, np.floating)) and math.isfinite(ensemble_decay) and ensemble_decay >= 0):
            raise ValueError(f"ensemble_decay (m) must be a finite number >= 0, got {ensemble_decay!r}")
        self.ensemble_decay = float(ensemble_decay)
        self.newest_first = bool(newest_first)

    @classmethod
    def from_spec(cls, predict_chunk: Callable[[Any], Any], spec: Any, delay: int = 0, **kwargs: Any) -> DelayedEnsemble:
        kwargs.setdefault("ensemble_decay", float(spec.ensemble_decay))
        return super().from_spec(predict_chunk, spec, delay=delay, **kwargs)

    def reset(self, obs: Any) -> None:
        super().reset(obs)
        self.chunks: list[Chunk] = []  # arrived chunks still covering the clock, oldest first

    def _take_arrived(self) -> None:
        """Move an arrived chunk into the ensemble (as float64 numpy, like TemporalEnsemble)."""
        if self._receive():
            self.current.actions = to_numpy(self.current.actions)  # (B, L, Da)
            self.chunks.append(self.current)

    def act(self, obs: Any) -> Any:
        self._observe(obs)
        t = self.t
        self._take_arrived()
        if self.pending is None and t >= self.next_request:
            self._request()
            self.next_request = t + max(1, self.delay)
            self._take_arrived()  # d = 0 (or the first request): usable at once
        self.chunks = [c for c in self.chunks if t - c.request < c.length]
        if not self.chunks:
            return self._emit(self.last_action)
        preds = np.stack([c.actions[:, t - c.request] for c in self.chunks], axis=0)  # (n, B, Da), oldest first
        i = np.arange(len(preds))
        if self.newest_first:
            i = i[::-1]
        w = np.exp(-self.ensemble_decay * i)  # (n,)
        w = w / w.sum()
        return self._emit(np.einsum("n,nbd->bd", w, preds))  # (B, Da), as TemporalEnsemble computes it
