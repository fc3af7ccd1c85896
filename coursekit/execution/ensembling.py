"""Temporal ensembling: query the policy every step and average every chunk's guess for now.

ACT (Zhao et al. 2023, Sec. IV-A, Fig. 5) predicts a chunk of k actions at every control step
instead of every k steps. At time t, up to k chunks (made at steps t-k+1 ... t) each hold one
prediction for time t; the executed action is their weighted average::

    chunk made at step s:      s    s+1   s+2   ...  s+k-1
    prediction for time t:     chunk_s[t - s]          (needs s <= t < s + k)

    a_t = sum_i w_i * pred_i / sum_i w_i,    w_i = exp(-m * i),   m = ensemble_decay

where the predictions are ordered OLDEST FIRST: i = 0 is the oldest chunk still covering t, so
the oldest guess weighs most (as in the original code, whose comment says "new actions
weighted less"). ``newest_first=True`` reverses the order (i = 0 is the newest chunk), an
option several reproductions prefer. m = 0 is the plain mean; a large m approaches open-loop
execution of the oldest chunk (or, with ``newest_first``, of the newest one).

The executor works with ANY chunk predictor ``(B, To, Do) -> (B, Tp, Da)``, so Diffusion
Policy can be ensembled too: a chunk whose first To - 1 steps lie in the past (Diffusion
Policy predicts from the first observed step) is read from ``start = To - 1`` on, exactly as
:class:`~coursekit.execution.receding.RecedingHorizon` does.

Protocol (shared with ``RecedingHorizon``): ``reset(obs (B, Do))`` at the start of an episode,
then ``act(obs (B, Do)) -> (B, Da)`` once per control step; B environments step in lock-step.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from coursekit.execution.receding import batch_size_of, observation_arrays, stack_history, to_numpy


class TemporalEnsemble:
    """Executor that queries a chunk predictor every step and ensembles the overlapping chunks.

    Args:
        predict_chunk: callable mapping an observation history (B, To, Do) to a chunk
            (B, Tp, Da) in raw action units (numpy array or torch tensor).
        n_obs_steps: To, observation steps the predictor conditions on (ACT: 1).
        ensemble_decay: m >= 0 in w_i = exp(-m i) (ACT: 0.01).
        newest_first: False (original ACT): i = 0 is the OLDEST prediction, which then weighs
            most. True: i = 0 is the NEWEST prediction.
        start: index in each chunk of the action for the step the chunk was made at
            (default To - 1; 0 for ACT).

    State after ``reset``: the last To observations, the step counter t, and every chunk made
    in the last Tp - start steps together with the step it was made at.
    """

    def __init__(self, predict_chunk: Callable[[Any], Any], n_obs_steps: int = 1, ensemble_decay: float = 0.01,
                 newest_first: bool = False, start: int | None = None) -> None:
        if not callable(predict_chunk):
            raise ValueError(f"predict_chunk must be callable (B, To, Do) -> (B, Tp, Da), got {predict_chunk!r}")
        if not isinstance(n_obs_steps, (int, np.integer)) or n_obs_steps < 1:
            raise ValueError(f"n_obs_steps must be a positive integer, got {n_obs_steps!r}")
        if not np.isfinite(ensemble_decay) or ensemble_decay < 0:
            raise ValueError(f"ensemble_decay (m) must be a finite number >= 0, got {ensemble_decay!r}")
        start = n_obs_steps - 1 if start is None else start
        if not isinstance(start, (int, np.integer)) or start < 0:
            raise ValueError(f"start must be a non-negative integer, got {start!r}")
        self.predict_chunk = predict_chunk
        self.n_obs_steps = int(n_obs_steps)
        self.ensemble_decay = float(ensemble_decay)
        self.newest_first = bool(newest_first)
        self.start = int(start)
        self._history: list[Any] | None = None  # To observations (B, Do), or dicts of (B, ...) arrays, oldest first
        self._chunks: list[tuple[int, np.ndarray]] = []  # (step made at, (B, Tp - start, Da))
        self.t = 0

    @classmethod
    def from_spec(cls, predict_chunk: Callable[[Any], Any], spec: Any) -> TemporalEnsemble:
        """The executor every policy builds: To and m from an :class:`~coursekit.execution.spec.ExecutionSpec`."""
        return cls(predict_chunk, n_obs_steps=int(spec.n_obs_steps), ensemble_decay=float(spec.ensemble_decay))

    def reset(self, obs: Any) -> None:
        """Start an episode: history = To copies of ``obs`` (B, Do), or of a dict of (B, ...) arrays
        (an image policy's {"image", "agent_pos"}, kept in their own dtype); forget every chunk."""
        obs = observation_arrays(obs)
        if not isinstance(obs, dict) and obs.ndim != 2:
            raise ValueError(f"reset expects obs of shape (B, Do), got {obs.shape}")
        self._history = [obs] * self.n_obs_steps
        self._chunks = []
        self.t = 0

    def _observe(self, obs: Any) -> Any:
        """Shift ``obs`` (B, Do) into the history and return it, (B, To, Do) (a dict: key by key)."""
        if self._history is None:
            raise ValueError("act() called before reset(obs): call reset with the first observation")
        obs, last = observation_arrays(obs), self._history[-1]
        shapes = ({k: v.shape for k, v in obs.items()} if isinstance(obs, dict) else obs.shape,
                  {k: v.shape for k, v in last.items()} if isinstance(last, dict) else last.shape)
        if shapes[0] != shapes[1]:
            raise ValueError(f"act expects obs of shape {shapes[1]} (B, Do), got {shapes[0]}")
        self._history = [*self._history[1:], obs]
        return stack_history(self._history)  # (B, To, Do)

    def act(self, obs: Any) -> np.ndarray:
        """One control step at time t = self.t: predict a chunk, return the ensembled action (B, Da).

        Steps: (1) store the new chunk (B, Tp, Da) from ``self.start`` on, with the step t it was
        made at, in ``self._chunks`` (a list of (s, chunk) pairs, oldest first); (2) forget chunks
        that no longer reach t (a chunk c made at s covers s .. s + len(c) - 1); (3) the
        prediction of chunk (s, c) for time t is ``c[:, t - s]``; with n of them, oldest first,
        weights w_i = exp(-m i) for i = 0 .. n-1 (m = ``self.ensemble_decay``; i counted from the
        NEWEST when ``self.newest_first``), normalised to sum to 1; (4) the action is
        sum_i w_i * pred_i, shape (B, Da). ``self.t`` is advanced after your block.
        """
        history = self._observe(obs)
        chunk = to_numpy(self.predict_chunk(history))  # (B, Tp, Da)
        B = batch_size_of(history)
        if chunk.ndim != 3 or chunk.shape[0] != B or chunk.shape[1] <= self.start:
            raise ValueError(f"predict_chunk must return (B={B}, Tp > start={self.start}, Da), got {chunk.shape}")
        # BEGIN SOLUTION
        t = self.t
        self._chunks.append((t, chunk[:, self.start:]))  # keep only steps from "now" on: (B, Tp - start, Da)
        # drop chunks that no longer cover time t (made at s with s + len <= t)
        self._chunks = [(s, c) for s, c in self._chunks if t - s < c.shape[1]]
        preds = np.stack([c[:, t - s] for s, c in self._chunks], axis=0)  # (n, B, Da), oldest first
        i = np.arange(len(preds))
        if self.newest_first:
            i = i[::-1]  # i = 0 for the newest chunk
        w = np.exp(-self.ensemble_decay * i)  # (n,)
        w = w / w.sum()
        action = np.einsum("n,nbd->bd", w, preds)  # (B, Da)
        # END SOLUTION
        self.t += 1
        return action

