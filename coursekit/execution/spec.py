"""How a chunk policy wants to be executed, and the one horizon rule every executor relies on.

Every executor class is built the same way, from the policy's :class:`ExecutionSpec`::

    executor = ExecutorClass.from_spec(predict_chunk, policy.execution_spec())

so a policy (or a notebook) can swap in any executor -- the library's or a student's -- without
knowing its constructor. ``temporal_ensembling`` picks the policy's DEFAULT executor class;
the spec carries every setting either kind needs (To, Ta, m).

The horizon rule (Chi et al. 2023, Sec. 3.1): a chunk of Tp actions is aligned with the oldest
of the To observations, so the executed slice ``pred[To-1 : To-1+Ta]`` must fit in the chunk::

    To - 1 + Ta <= Tp
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def check_horizons(n_obs_steps: int, horizon: int, n_action_steps: int) -> None:
    """Refuse To, Tp, Ta that are not positive ints or break ``To - 1 + Ta <= Tp`` (ValueError showing them)."""
    for name, v in (("n_obs_steps", n_obs_steps), ("horizon", horizon), ("n_action_steps", n_action_steps)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    if n_obs_steps - 1 + n_action_steps > horizon:
        raise ValueError(f"To - 1 + Ta must fit in Tp: n_obs_steps={n_obs_steps}, n_action_steps={n_action_steps}, "
                         f"horizon={horizon}")


@dataclass(frozen=True)
class ExecutionSpec:
    """Everything an executor needs to know about the policy it drives."""

    n_obs_steps: int
    """To: observations in the history passed to predict_chunk."""
    horizon: int
    """Tp (ACT: k): actions in each predicted chunk."""
    n_action_steps: int
    """Ta: actions executed from a chunk before re-planning (receding horizon)."""
    temporal_ensembling: bool = False
    """The policy's default executor: temporal ensembling (True, ACT) or receding horizon (False)."""
    ensemble_decay: float = 0.01
    """m in w_i = exp(-m i) for temporal ensembling (ACT's 0.01)."""

    @property
    def usable_horizon(self) -> int:
        """H = Tp - To + 1: the actions of a chunk at or after the step it was requested at (the
        first To - 1 are for observed, past steps); RTC's regime is d <= s <= H - d."""
        return self.horizon - (self.n_obs_steps - 1)

    def __post_init__(self) -> None:
        check_horizons(self.n_obs_steps, self.horizon, self.n_action_steps)
        if not (np.isfinite(self.ensemble_decay) and self.ensemble_decay >= 0):
            raise ValueError(f"ensemble_decay (m) must be a finite number >= 0, got {self.ensemble_decay!r}")
