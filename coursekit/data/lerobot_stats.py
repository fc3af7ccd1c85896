"""Feature statistics as LeRobot keeps them: meta/stats.json and the per-episode ``stats/`` columns.

For every feature: ``min``, ``max``, ``mean``, ``std``, ``count`` and the quantiles ``q01``,
``q10``, ``q50``, ``q90``, ``q99``, each over the frames, per dimension (shape (d,); (1,) for a
scalar). Images are per colour channel over frames and pixels, scaled to [0, 1], shape (3, 1, 1),
from at most :data:`IMAGE_SAMPLES` evenly spaced frames (LeRobot also samples frames for images).
LeRobot normalises a policy's inputs with these numbers; coursekit computes exact quantiles
(``numpy.quantile``), LeRobot approximates them with histograms, so the two differ by a bin width.
"""

from __future__ import annotations

from typing import Any

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
"""Quantiles LeRobot stores, named q01, q10, q50, q90, q99."""
IMAGE_SAMPLES = 100
"""Most frames an image statistic reads (evenly spaced)."""


def feature_stats(values: np.ndarray, image: bool = False) -> dict[str, np.ndarray]:
    """Statistics of one feature's frames: values (N,) or (N, d), or images (N, H, W, 3) uint8."""
    n = len(values)
    if image:
        picked = values[np.unique(np.linspace(0, n - 1, min(n, IMAGE_SAMPLES)).round().astype(int))]
        x = picked.reshape(-1, picked.shape[-1]).astype(np.float64) / 255.0  # (frames * H * W, 3)
    else:
        x = np.asarray(values, dtype=np.float64).reshape(n, -1)  # (N, d); bool -> 0/1
    stats = {"min": x.min(axis=0), "max": x.max(axis=0), "mean": x.mean(axis=0), "std": x.std(axis=0),
             "count": np.array([n], dtype=np.int64)}
    for q, value in zip(QUANTILES, np.quantile(x, QUANTILES, axis=0), strict=True):
        stats[f"q{round(q * 100):02d}"] = value
    if image:
        stats = {k: v if k == "count" else v.reshape(3, 1, 1) for k, v in stats.items()}
    return stats


def stats_to_json(stats: dict[str, dict[str, np.ndarray]]) -> dict[str, dict[str, Any]]:
    """{feature: {stat: array}} -> nested lists for json."""
    return {key: {name: value.tolist() for name, value in per.items()} for key, per in stats.items()}


def episode_stats_columns(key: str, values: np.ndarray, starts: np.ndarray, ends: np.ndarray,
                          image: bool = False) -> dict[str, list]:
    """The ``stats/<key>/<stat>`` columns of meta/episodes: one list per episode and statistic."""
    per_episode = [feature_stats(values[s:e], image=image) for s, e in zip(starts, ends, strict=True)]
    return {f"stats/{key}/{name}": [st[name].tolist() for st in per_episode] for name in per_episode[0]}
