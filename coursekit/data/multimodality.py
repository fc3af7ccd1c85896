"""How multimodal is a PushT data set? The fraction of states the demonstrations leave two ways.

Chi et al. (2023, Sec. 4 and Fig. 3) argue that a mean regressor fails where demonstrations
leave one situation in different directions. This module makes "how often" a number.

Definition (every constant is a field of :class:`MultimodalityConfig`):

1. A state is what a policy with To = 2 sees: the pusher position, its last step scaled by
   ``velocity_scale`` (so that pushing in and backing off from the same spot differ), the
   block position and the block angle as a point on a circle of radius ``angle_scale`` px:
   z = [ax, ay, c dax, c day, bx, by, L cos(theta), L sin(theta)] (dax: 0 at an episode's start).
2. The **neighbours** of a query row are, for every demonstration (the query's own included),
   its nearest row within ``radius`` of the query in z (Euclidean, px): one row per episode,
   so that one slow demonstration cannot outvote the others. A query with fewer than
   ``min_episodes`` neighbours is *unsupported* (the data are too thin there to say).
3. A neighbour row j **heads** along v_j = a[j + H - 1] - p_j, the pusher target H =
   ``horizon`` steps on (the end of one executed chunk, Ta = 8) minus the pusher position
   now, within its own episode. |v_j| < ``still_px``: it stays put and has no direction.
4. The query is **two-way** when the moving neighbours split: with u* the direction (among
   the neighbours' own) that has the most neighbours within ``mode_deg`` of it, at least
   ``min_fraction`` of the moving neighbours (and at least two) head more than ``split_deg``
   away from u*. Here a mean of the neighbours' chunks lies between the two groups.

:func:`two_way_fraction` applies it to query rows sampled from the travel and push phases
(settling and the final rest are the expert's, not a choice) and returns the fraction with
an interval from a bootstrap over demonstrations (rows of one episode are not independent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PUSHER_PHASES = (1, 2)
"""Phases (``pusht_recording``: 1 travel, 2 push) whose rows are queried; settle and rest are not choices."""


@dataclass(frozen=True)
class MultimodalityConfig:
    """The constants of the two-way definition (module docstring, steps 1-4)."""

    radius: float = 20.0
    """Neighbourhood radius in state space (px; the angle counts at ``angle_scale`` px per radian)."""
    angle_scale: float = 50.0
    """L: px per radian of block angle (about the T's half length: a turn of 1 rad moves its tips ~50 px)."""
    velocity_scale: float = 2.0
    """c: px of state distance per px/step of pusher motion over the last step (To = 2)."""
    min_episodes: int = 6
    """Fewest demonstrations (one row each) a query needs to be supported."""
    horizon: int = 8
    """H: steps ahead whose pusher target gives a neighbour's heading (one executed chunk, Ta = 8)."""
    still_px: float = 10.0
    """A heading shorter than this (px) counts as staying put (no direction)."""
    mode_deg: float = 45.0
    """Half-width of the main mode: neighbours within this angle of u* belong to it."""
    split_deg: float = 90.0
    """Neighbours heading more than this angle from u* go another way."""
    min_fraction: float = 0.25
    """Fewest moving neighbours (as a fraction) that must go another way for the query to be two-way."""
    n_queries: int = 2000
    """Query rows sampled (seeded) from the travel and push phases."""

    def __post_init__(self) -> None:
        for name in ("radius", "angle_scale", "velocity_scale", "still_px"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {getattr(self, name)!r}")
        for name in ("min_episodes", "horizon", "n_queries"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                raise ValueError(f"{name} must be an int >= 1, got {getattr(self, name)!r}")
        if not 0 < self.mode_deg < self.split_deg <= 180:
            raise ValueError(f"need 0 < mode_deg < split_deg <= 180, got {self.mode_deg!r}, {self.split_deg!r}")
        if not 0 < self.min_fraction <= 0.5:
            raise ValueError(f"min_fraction must be in (0, 0.5], got {self.min_fraction!r}")


@dataclass(frozen=True)
class Multimodality:
    """The two-way fraction of one data set."""

    fraction: float
    """Two-way queries / supported queries."""
    lo: float
    """2.5 % point of the bootstrap over demonstrations."""
    hi: float
    """97.5 % point of the bootstrap over demonstrations."""
    n_supported: int
    """Supported queries (the denominator)."""
    n_queries: int
    """Queries sampled."""
    two_way: np.ndarray
    """(n_queries,) int8: 1 two-way, 0 one-way, -1 unsupported."""
    query_rows: np.ndarray
    """(n_queries,) int64 row index of each query in the data set."""


def state_features(state: np.ndarray, starts: np.ndarray, config: MultimodalityConfig) -> np.ndarray:
    """(N, 5) [ax, ay, bx, by, theta] rows of episodes beginning at ``starts`` -> (N, 8) z of step 1 (px)."""
    step = np.diff(state[:, :2], axis=0, prepend=state[:1, :2])  # (N, 2) pusher motion over the last step
    step[starts] = 0.0  # an episode's first row has no last step
    theta = state[:, 4]
    return np.column_stack([state[:, :2], config.velocity_scale * step, state[:, 2:4],
                            config.angle_scale * np.cos(theta), config.angle_scale * np.sin(theta)])  # (N, 8)


def headings(state: np.ndarray, action: np.ndarray, ends: np.ndarray, horizon: int) -> np.ndarray:
    """(N, 2) v_j of step 3: the target ``horizon`` steps on (clipped at the episode's end) minus p_j."""
    starts = np.concatenate([[0], ends[:-1]])
    episode = np.repeat(np.arange(len(ends)), ends - starts)  # (N,)
    ahead = np.minimum(np.arange(len(state)) + horizon - 1, ends[episode] - 1)  # (N,)
    return action[ahead] - state[:, :2]  # (N, 2)


def is_two_way(vectors: np.ndarray, config: MultimodalityConfig) -> bool:
    """Step 4 on the neighbours' headings ``vectors`` (K, 2)."""
    moving = vectors[np.linalg.norm(vectors, axis=1) >= config.still_px]  # (M, 2)
    if len(moving) < 2:
        return False
    unit = moving / np.linalg.norm(moving, axis=1, keepdims=True)
    cos = np.clip(unit @ unit.T, -1.0, 1.0)  # (M, M): cosine between every pair of headings
    main = int(np.argmax((cos >= math.cos(math.radians(config.mode_deg))).sum(axis=1)))
    other = int((cos[main] < math.cos(math.radians(config.split_deg)) - 1e-9).sum())  # strictly more than split_deg
    return other >= max(2, math.ceil(config.min_fraction * len(moving)))


class Neighbourhoods:
    """A PushT data set in the definition's terms (steps 1-3), ready to answer queries about its rows."""

    def __init__(self, dataset, config: MultimodalityConfig | None = None) -> None:
        from scipy.spatial import cKDTree

        self.config = config or MultimodalityConfig()
        state, action = np.asarray(dataset["state"], float), np.asarray(dataset["action"], float)
        if state.ndim != 2 or state.shape[1] != 5 or action.shape != (len(state), 2):
            raise ValueError(f"expected PushT arrays state (N, 5) and action (N, 2), got {state.shape} and {action.shape}")
        ends = np.asarray(dataset.episode_ends)
        self.episode = np.repeat(np.arange(len(ends)), np.diff(np.concatenate([[0], ends])))  # (N,)
        self.z = state_features(state, np.concatenate([[0], ends[:-1]]), self.config)  # (N, 8)
        self.v = headings(state, action, ends, self.config.horizon)  # (N, 2)
        self.phase = np.asarray(dataset["phase"])  # (N,)
        self.tree = cKDTree(self.z)

    def neighbours(self, row: int) -> np.ndarray:
        """(K,) rows of step 2: the nearest row of each demonstration within ``radius`` of ``row``."""
        near = np.asarray(self.tree.query_ball_point(self.z[row], self.config.radius), dtype=np.int64)
        order = near[np.argsort(np.linalg.norm(self.z[near] - self.z[row], axis=1), kind="stable")]
        _, first = np.unique(self.episode[order], return_index=True)
        return order[first]  # by demonstration (step 4's tie-break between equal modes depends on this order)

    def verdict(self, row: int) -> int:
        """1 two-way, 0 one-way, -1 unsupported (fewer than ``min_episodes`` demonstrations near)."""
        rows = self.neighbours(row)
        if len(rows) < self.config.min_episodes:
            return -1
        return int(is_two_way(self.v[rows], self.config))


def two_way_fraction(dataset, config: MultimodalityConfig | None = None, seed: int = 0,
                     n_boot: int = 1000) -> Multimodality:
    """The two-way fraction of a PushT ``dataset`` (``EpisodeDataset`` with "state" (N, 5),
    "action" (N, 2), "phase" (N,)), on ``config.n_queries`` rows drawn with ``seed``.

    ``dataset`` may also be its :class:`Neighbourhoods` (then ``config`` is the one it was built
    with), so that a caller who draws the neighbours afterwards builds the KD-tree once."""
    if isinstance(dataset, Neighbourhoods):
        if config is not None and config != dataset.config:
            raise ValueError(f"config {config} differs from the Neighbourhoods' own {dataset.config}")
        hood = dataset
    else:
        hood = Neighbourhoods(dataset, config)
    candidates = np.flatnonzero(np.isin(hood.phase, PUSHER_PHASES))
    rng = np.random.default_rng(seed)
    rows = np.sort(rng.choice(candidates, size=min(hood.config.n_queries, len(candidates)), replace=False))
    verdict = np.array([hood.verdict(int(row)) for row in rows], dtype=np.int8)  # (Q,)
    return _summarise(verdict, rows, hood.episode, rng, n_boot)


def _summarise(verdict: np.ndarray, rows: np.ndarray, episode: np.ndarray, rng: np.random.Generator,
               n_boot: int) -> Multimodality:
    """Fraction over supported queries and a bootstrap interval that resamples whole episodes."""
    ok = verdict >= 0
    if not ok.any():
        raise ValueError("no query state has enough neighbouring demonstrations; collect more episodes or widen radius")
    q_episode = episode[rows][ok]  # (S,)
    hits = verdict[ok].astype(float)  # (S,)
    ids, inverse = np.unique(q_episode, return_inverse=True)
    per_hits = np.bincount(inverse, weights=hits, minlength=len(ids))  # (E',)
    per_n = np.bincount(inverse, minlength=len(ids)).astype(float)  # (E',)
    draws = rng.integers(len(ids), size=(n_boot, len(ids)))  # (B, E') episodes resampled
    boot = per_hits[draws].sum(axis=1) / per_n[draws].sum(axis=1)  # (B,)
    return Multimodality(fraction=float(hits.mean()), lo=float(np.quantile(boot, 0.025)),
                         hi=float(np.quantile(boot, 0.975)), n_supported=int(ok.sum()), n_queries=len(rows),
                         two_way=verdict, query_rows=rows)
