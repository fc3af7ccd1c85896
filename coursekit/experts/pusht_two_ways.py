"""Where PushT is multimodal: starts whose first decision is a coin toss, and which way a path goes.

Chi et al. (2023, Fig. 3) argue from one picture: from some starts a demonstrator goes round the
T clockwise or anticlockwise, and a regressor averages the two. The course's scripted expert
knows exactly when that happens (``PushTExpert.choose_sides``: both sides within
``route_tolerance`` of each other, a seeded coin picks), so the multimodal starts can be listed
rather than guessed:

- :func:`first_decision` runs the (clean, deterministic) expert from a reset seed and reports
  whether its FIRST travel leg was such a two-way choice (``two_way``), and which side it went.
- :func:`path_sweep` / :func:`path_side`: which way round the T a path of pusher targets goes,
  by the signed angle it sweeps about the T's centre of gravity in the T's own frame (the
  planner's own convention: > 0 is clockwise on screen, y down). A chunk that sweeps less than
  ``min_sweep`` either way goes round neither side ("none"): it heads at the T, or stays put.

Benchmarks cache :func:`first_decision` per seed (``benchmarks/two_way_starts.json``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coursekit.envs import pusht_geometry as geo
from coursekit.experts.pusht_recording import TRAVEL
from coursekit.experts.pusht_routes import ANTICLOCKWISE, CLOCKWISE

NEITHER = "none"
"""Side of a path that sweeps less than ``min_sweep`` about the T's centre of gravity."""
MIN_SWEEP = math.radians(20.0)
"""Default angle (rad) a path must sweep about the T's centre of gravity to count as going round it."""


@dataclass(frozen=True)
class FirstDecision:
    """What the clean expert does first from one reset seed."""

    seed: int
    """Reset seed (``env.reset(seed=seed)``)."""
    two_way: bool
    """The first travel leg was a coin toss between clockwise and anticlockwise (both open, about equally long)."""
    side: str
    """Side of the first travel leg by :func:`path_side` ("cw", "ccw" or "none": straight or no travel)."""
    any_two_way: bool
    """Some travel leg of the episode was a coin toss (``bench_pusht_expert``'s count)."""
    success: bool
    """The expert solved the reset (coverage > 0.95 within its step limit)."""


def path_sweep(points: np.ndarray, block_pose) -> float:
    """Signed angle (rad) the polyline ``points`` (K, 2) (world px) turns about the T's centre of
    gravity at ``block_pose`` (x, y, angle); > 0: clockwise on screen (:func:`geo.swept_angle`)."""
    return geo.swept_angle(points, block_pose)


def path_side(points: np.ndarray, block_pose, min_sweep: float = MIN_SWEEP) -> str:
    """"cw", "ccw" or "none": which way round the T the path ``points`` (K, 2) heads (see :func:`path_sweep`)."""
    if not min_sweep > 0:
        raise ValueError(f"min_sweep must be a positive angle (rad), got {min_sweep!r}")
    sweep = path_sweep(points, block_pose)
    return CLOCKWISE if sweep >= min_sweep else ANTICLOCKWISE if sweep <= -min_sweep else NEITHER


def first_decision(seed: int, expert=None, env=None) -> FirstDecision:
    """Run the clean expert (coin seed = reset seed) from ``env.reset(seed=seed)`` and describe its first travel leg."""
    from coursekit.envs.pusht import PushTEnv
    from coursekit.experts.pusht_planner import PushTExpert

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    expert = expert or PushTExpert()
    env = env or PushTEnv(obs_type="state", max_episode_steps=expert.config.max_steps)
    rec = expert.run_episode(env, int(seed))
    travel = np.flatnonzero(rec.phases == TRAVEL)
    if len(travel) == 0:
        return FirstDecision(int(seed), False, NEITHER, bool(rec.route_choices), rec.success_step is not None)
    start = int(travel[0])
    stop = start + int(np.argmax(rec.phases[start:] != TRAVEL)) if (rec.phases[start:] != TRAVEL).any() else len(rec.phases)
    two_way = bool(rec.route_choices) and int(rec.route_choices[0]["step"]) == start
    leg = np.concatenate([rec.states[start, None, :2], rec.actions[start:stop]])  # (L+1, 2): pusher, then targets
    side = path_side(leg, rec.states[start, 2:5]) if len(leg) >= 2 else NEITHER
    return FirstDecision(int(seed), two_way, side, bool(rec.route_choices), rec.success_step is not None)


def two_way_table(seeds) -> list[FirstDecision]:
    """:func:`first_decision` for each seed (one expert and env reused; about 0.1 s per seed)."""
    from coursekit.envs.pusht import PushTEnv
    from coursekit.experts.pusht_planner import PushTExpert

    expert = PushTExpert()
    env = PushTEnv(obs_type="state", max_episode_steps=expert.config.max_steps)
    return [first_decision(int(s), expert, env) for s in seeds]
