"""Receding-horizon execution of action chunks (Diffusion Policy, Chi et al. 2023, Sec. 3.1).

A chunk policy predicts Tp actions from the last To observations, but only Ta of them are
executed before it re-plans from fresh observations::

    step      t-1   t    t+1  ...  t+7   t+8  ...  t+14
    history  [o    o]                                          To = 2 observations in
    chunk    [a    a    a    ...  a    a    ...  a]            Tp = 16 actions out
    executed      [a    a    ...  a]                           Ta = 8 from index To - 1
                                      ^ re-plan here with the newest To observations

The executed slice is ``pred[To-1 : To-1+Ta]``: action 0 of a chunk is aligned with the oldest
observation of the history (t - To + 1), so action To - 1 is the one for "now". At reset the
history is filled with To copies of the first observation (as in training, where windows at an
episode start repeat its first step).

The executor works with ANY chunk predictor ``predict_chunk(obs_history) -> chunk`` with
``obs_history`` (B, To, Do) and ``chunk`` (B, Tp, Da), batched over B environments: one call
per re-plan for all environments at once. Observations may be numpy arrays, torch tensors or
dicts of them (image policies: {"image": (B, 3, H, W), "agent_pos": (B, 2)}).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any


def stack_history(history: Sequence[Any]) -> Any:
    """A list of To observations, each (B, ...), -> one (B, To, ...) batch, oldest first.

    Works on numpy arrays, torch tensors, and dicts of either (stacked key by key).
    """
    first = history[0]
    if isinstance(first, dict):
        return {k: stack_history([h[k] for h in history]) for k in first}
    if hasattr(first, "new_tensor"):  # torch.Tensor, without importing torch here
        import torch

        return torch.stack(list(history), dim=1)  # (B, To, ...)
    import numpy as np

    return np.stack(history, axis=1)  # (B, To, ...)


def to_numpy(x: Any) -> Any:
    """A float64 numpy array from a numpy array or a torch tensor (without importing torch)."""
    import numpy as np

    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def observation_arrays(obs: Any) -> Any:
    """An observation batch as float64 numpy (B, Do), or a dict of numpy arrays in their own dtype
    (uint8 frames stay uint8: a policy reads 0..255 floats as out of range)."""
    import numpy as np

    if isinstance(obs, dict):
        return {k: v.detach().cpu().numpy() if hasattr(v, "detach") else np.asarray(v) for k, v in obs.items()}
    return to_numpy(obs)


def batch_size_of(obs: Any) -> int:
    """B of an observation batch (B, ...) or of a dict of them."""
    if isinstance(obs, dict):
        return batch_size_of(next(iter(obs.values())))
    return int(obs.shape[0])


class RecedingHorizon:
    """Turn a chunk predictor into one action per step: execute Ta actions, then re-plan.

    Args:
        predict_chunk: callable (B, To, ...) observation history -> (B, Tp, Da) chunk.
        n_obs_steps: To, observations in the history.
        n_action_steps: Ta, actions executed per chunk before re-planning.
        start: index of the first executed action in the chunk (default To - 1, see module doc).

    Use: ``reset(obs0)`` with the first observation (B, ...), then ``act(obs_t)`` every step,
    the first step included, with the current observation; it returns the action (B, Da).
    """

    def __init__(self, predict_chunk: Callable[[Any], Any], n_obs_steps: int = 2, n_action_steps: int = 8,
                 start: int | None = None):
        if not callable(predict_chunk):
            raise ValueError(f"predict_chunk must be callable (B, To, Do) -> (B, Tp, Da), got {predict_chunk!r}")
        if not isinstance(n_obs_steps, int) or n_obs_steps < 1:
            raise ValueError(f"n_obs_steps (To) must be a positive int, got {n_obs_steps!r}")
        if not isinstance(n_action_steps, int) or n_action_steps < 1:
            raise ValueError(f"n_action_steps (Ta) must be a positive int, got {n_action_steps!r}")
        start = n_obs_steps - 1 if start is None else start
        if not isinstance(start, int) or start < 0:
            raise ValueError(f"start must be a non-negative int, got {start!r}")
        self.predict_chunk = predict_chunk
        self.n_obs_steps = n_obs_steps
        self.n_action_steps = n_action_steps
        self.start = start
        self.history: list[Any] = []
        self.plan: Any = None  # (B, Ta, Da) actions still to execute, or None
        self.plan_index = 0  # how many actions of ``plan`` have been executed
        self.n_calls = 0  # chunk predictions made since reset (for latency accounting)

    @classmethod
    def from_spec(cls, predict_chunk: Callable[[Any], Any], spec: Any) -> RecedingHorizon:
        """The executor every policy builds: To and Ta from an :class:`~coursekit.execution.spec.ExecutionSpec`."""
        return cls(predict_chunk, n_obs_steps=int(spec.n_obs_steps), n_action_steps=int(spec.n_action_steps))

    def _predict(self) -> Any:
        """Call the predictor on the current history and check the chunk's shape."""
        obs_history = stack_history(self.history)  # (B, To, ...)
        chunk = self.predict_chunk(obs_history)  # (B, Tp, Da)
        b = batch_size_of(obs_history)
        shape = tuple(getattr(chunk, "shape", ()))
        if len(shape) != 3 or shape[0] != b or shape[1] < self.start + self.n_action_steps:
            raise ValueError(
                f"predict_chunk returned shape {shape}; expected (B={b}, Tp, Da) with "
                f"Tp >= start + Ta = {self.start} + {self.n_action_steps}"
            )
        self.n_calls += 1
        return chunk

    def reset(self, obs: Any) -> None:
        """Start an episode: ``self.history`` becomes a list of To copies of the first observation ``obs`` (B, ...).

        Also forget any plan left from the last episode (``self.plan = None``, ``self.plan_index = 0``),
        so the first ``act`` re-plans at once.
        """
        # BEGIN SOLUTION
        self.history = [obs] * self.n_obs_steps
        self.plan = None
        self.plan_index = 0
        # END SOLUTION
        self.n_calls = 0

    def act(self, obs: Any) -> Any:
        """Push ``obs`` (B, ...) into the history; return the next action ``action`` (B, Da).

        1. history <- history[1:] + [obs]   (keep the newest To observations, oldest first)
        2. if no planned action is left (first call after reset, or Ta actions executed):
           chunk = self._predict()           (B, Tp, Da): the predictor on the stacked history
           plan  = chunk[:, start : start + Ta]   (B, Ta, Da), start = To - 1 by default
        3. action = the next unexecuted action of the plan, (B, Da)

        State to keep: ``self.history`` (list of To observations), ``self.plan`` and
        ``self.plan_index`` (how many actions of the plan were executed).
        """
        if not self.history:
            raise ValueError("act() called before reset(obs): call reset with the first observation")
        # BEGIN SOLUTION
        self.history = [*self.history[1:], obs]  # drop the oldest, keep To observations
        if self.plan is None or self.plan_index >= self.n_action_steps:
            chunk = self._predict()  # (B, Tp, Da)
            self.plan = chunk[:, self.start : self.start + self.n_action_steps]  # (B, Ta, Da)
            self.plan_index = 0
        action = self.plan[:, self.plan_index]  # (B, Da)
        self.plan_index += 1
        # END SOLUTION
        return action
