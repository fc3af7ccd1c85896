"""Evaluation outcomes and the held-out seed protocol, shared by every task.

Held-out seeds: episode i of an evaluation uses reset seed ``EVAL_SEED_START + i`` = 100000 + i.
Demonstrations are collected from small seeds (``coursekit collect ... --seed S`` uses seeds
S .. S + n - 1, S = 0 by default), so the two sets are disjoint; :func:`check_seeds_disjoint`
checks it against the dataset metadata stored in the checkpoint and refuses an overlap.
Variants are chosen on a separate validation range (200000+), never on the reported one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

EVAL_SEED_START = 100_000
"""First held-out evaluation seed (episode i uses EVAL_SEED_START + i)."""


def heldout_seeds(n_episodes: int = 50, start: int = EVAL_SEED_START) -> list[int]:
    """The reset seeds of an n-episode evaluation: start, start + 1, ..."""
    if not isinstance(n_episodes, int) or n_episodes < 1:
        raise ValueError(f"n_episodes must be a positive int, got {n_episodes!r}")
    return list(range(start, start + n_episodes))


@dataclass
class EvalResult:
    """Per-episode outcomes of an evaluation.

    Attributes:
        seeds: (N,) reset seeds.
        max_reward: (N,) maximum reward reached in each episode.
        success: (N,) whether each episode succeeded (info["is_success"] at some step).
        length: (N,) steps each episode ran (until success or the step limit).
        seconds: wall-clock time of the whole evaluation.
        chunk_calls: calls of the chunk predictor (each for all N environments at once).
        chunk_seconds: time spent inside the chunk predictor.
        states: (N, T + 1, S) recorded simulator states (``record=True``), else None.
        actions: (N, T, Da) executed actions (``record=True``), else None.
        info: free-form extras (sampler, steps, checkpoint, ...).
    """

    seeds: list[int]
    max_reward: np.ndarray
    success: np.ndarray
    length: np.ndarray
    seconds: float
    chunk_calls: int
    chunk_seconds: float
    states: np.ndarray | None = None
    actions: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def score(self) -> float:
        """Mean over episodes of the max reward (the paper's PushT score)."""
        return float(np.mean(self.max_reward))

    @property
    def success_rate(self) -> float:
        return float(np.mean(self.success))

    @property
    def ms_per_chunk(self) -> float:
        """Average milliseconds per chunk-predictor call (batched over all environments)."""
        return 1000.0 * self.chunk_seconds / max(1, self.chunk_calls)

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary: score, success rate, standard error, episodes, timing."""
        n = len(self.seeds)
        return {"score": round(self.score, 4), "success_rate": round(self.success_rate, 4),
                "score_stderr": round(float(np.std(self.max_reward, ddof=1) / np.sqrt(n)) if n > 1 else 0.0, 4),
                "episodes": n, "seeds": f"{self.seeds[0]}..{self.seeds[-1]}", "seconds": round(self.seconds, 2),
                "chunk_calls": self.chunk_calls, "ms_per_chunk": round(self.ms_per_chunk, 2), **self.info}

    def __repr__(self) -> str:
        return (f"EvalResult(score={self.score:.3f}, success_rate={self.success_rate:.2f}, "
                f"episodes={len(self.seeds)}, seconds={self.seconds:.1f})")


def check_seeds_disjoint(seeds: Sequence[int], dataset_meta: dict[str, Any] | None) -> None:
    """Refuse evaluation seeds that were demonstration seeds (meta "episode_seeds", or "seed" + "n_episodes")."""
    if not dataset_meta:
        return
    if not isinstance(dataset_meta, dict):
        raise ValueError(f"the demonstrations' meta must be a dict, got {type(dataset_meta).__name__}")
    if "episode_seeds" in dataset_meta:  # the expert skips a failed seed and moves on: use the list
        listed = dataset_meta["episode_seeds"]
        if not isinstance(listed, (list, tuple)) or not all(_is_int(s) for s in listed):
            raise ValueError(f"the demonstrations' meta 'episode_seeds' must be a list of ints, got {str(listed)[:60]!r}")
        used = {int(s) for s in listed}
    elif "seed" in dataset_meta and "n_episodes" in dataset_meta:
        seed, n = dataset_meta["seed"], dataset_meta["n_episodes"]
        if not (_is_int(seed) and _is_int(n) and 0 <= n <= 10**7):
            raise ValueError(f"the demonstrations' meta 'seed' and 'n_episodes' must be ints (n_episodes in [0, 1e7]), "
                             f"got {str(seed)[:30]!r} and {str(n)[:30]!r}")
        used = set(range(seed, seed + n))
    else:
        return
    if not used:
        return
    overlap = sorted(int(s) for s in seeds if int(s) in used)
    if overlap:
        raise ValueError(f"evaluation seeds {overlap[:5]}... were used for the demonstrations (seeds {min(used)}..{max(used)}); "
                         f"evaluate on held-out seeds (default: from {EVAL_SEED_START})")


def _is_int(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)
