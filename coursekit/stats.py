"""Confidence intervals for evaluation figures: how far a score on N seeds can be trusted.

The course reports every success rate and mean score with a 95 % interval and its seed count
(50 episodes give a standard error near 0.05 — too thin to rank two policies).

- Success rates: the Wilson score interval (Wilson 1927), which stays inside [0, 1] and keeps
  its coverage near 0 and 1 where the normal ("Wald") interval collapses to a point.
- Mean scores in [0, 1] (PushT's mean of max coverage): a percentile bootstrap over episodes
  (Efron 1979) with a fixed seed, so the same scores always give the same interval.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np


def _z(level: float) -> float:
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    return NormalDist().inv_cdf(0.5 + level / 2.0)


def wilson_interval(successes: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a success rate ``successes / n``.

    lo, hi = (p + z^2/2n -+ z * sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n), p = successes / n.
    """
    if isinstance(n, bool) or int(n) != n or n <= 0:
        raise ValueError(f"n must be a positive integer, got {n!r}")
    if isinstance(successes, bool) or int(successes) != successes or not 0 <= successes <= n:
        raise ValueError(f"successes must be an integer in [0, n={n}], got {successes!r}")
    z = _z(level)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, float(centre - half)), min(1.0, float(centre + half))


def bootstrap_interval(values: Sequence[float], level: float = 0.95, n_resamples: int = 10_000,
                       seed: int = 0) -> tuple[float, float]:
    """Percentile-bootstrap interval of the mean of ``values`` (N,), deterministic by ``seed``."""
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"values must be a non-empty 1-D sequence, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"values must be finite, got {x[~np.isfinite(x)][:3].tolist()}")
    if n_resamples < 100:
        raise ValueError(f"n_resamples must be >= 100, got {n_resamples!r}")
    _z(level)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, x.size, size=(n_resamples, x.size))  # (R, N)
    means = x[idx].mean(axis=1)  # (R,)
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(means, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


@dataclass(frozen=True)
class Estimate:
    """A figure with its 95 % interval and the number of seeds it was measured on."""

    value: float
    """The point estimate (mean score, or success rate in [0, 1])."""
    lo: float
    """Lower end of the interval."""
    hi: float
    """Upper end of the interval."""
    n: int
    """Episodes (seeds) behind the figure."""

    def __str__(self) -> str:
        return f"{self.value:.3f} [{self.lo:.3f}, {self.hi:.3f}] (n={self.n})"


def mean_estimate(values: Sequence[float], level: float = 0.95, seed: int = 0) -> Estimate:
    """Mean of per-episode ``values`` with its bootstrap interval."""
    lo, hi = bootstrap_interval(values, level=level, seed=seed)
    x = np.asarray(values, dtype=np.float64)
    return Estimate(float(x.mean()), lo, hi, int(x.size))


def rate_estimate(successes: Sequence[bool], level: float = 0.95) -> Estimate:
    """Success rate of per-episode booleans with its Wilson interval."""
    s = np.asarray(successes)
    if s.ndim != 1 or s.size == 0 or s.dtype != np.bool_:
        raise ValueError(f"successes must be a non-empty 1-D boolean sequence, got dtype {s.dtype}, shape {s.shape}")
    k = int(s.sum())
    lo, hi = wilson_interval(k, int(s.size), level=level)
    return Estimate(k / s.size, lo, hi, int(s.size))
