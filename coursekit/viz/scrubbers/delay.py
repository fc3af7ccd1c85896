"""Chapter 11's scrubber: the inference delay d, on a stream of chunks that disagree.

A hand-built predictor stands in for the policy, so every executed action can be read off:
the chunk requested at step r predicts the "ideal" path x(r + j) = r + j plus an offset that
flips sign from chunk to chunk (+b, -b, +b, ...) — consecutive chunks agree on the trend but
not on the exact value, as two samples of a generative head do. Moving d redraws, in place,
what each strategy of :mod:`coursekit.execution.delay` executes: the synchronous robot's
pauses (flat steps, then it lags the ideal line), the naive asynchronous robot's jumps at each
switch (2b tall), and the delayed ensemble's average of the chunks that have arrived.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from coursekit.execution.delay import AsyncChunking, DelayedEnsemble, Synchronous
from coursekit.viz.scrubbers.figure import FigureScrubber

__all__ = ["DisagreeingChunks", "delay_scrubber", "play_delay"]


class DisagreeingChunks:
    """Predictor (B, To, 1) history -> (B, Tp, 1): chunk k from step r is r + j + (-1)^k b.

    The observation IS the step number (the executor feeds obs = t), so the chunk knows when it
    was requested, as a real policy knows from what it sees.
    """

    def __init__(self, horizon: int = 12, offset: float = 0.5):
        if horizon < 1:
            raise ValueError(f"horizon (Tp) must be >= 1, got {horizon!r}")
        self.horizon, self.offset, self.calls = int(horizon), float(offset), 0

    def __call__(self, obs_history: np.ndarray) -> np.ndarray:
        r = np.asarray(obs_history, dtype=np.float64)[:, -1, 0]  # (B,) step of the newest observation
        sign = 1.0 if self.calls % 2 == 0 else -1.0
        self.calls += 1
        chunk = r[:, None] + np.arange(self.horizon)[None, :] + sign * self.offset  # (B, Tp)
        return chunk[:, :, None]  # (B, Tp, 1)


def play_delay(strategy: str, delay: int, steps: int = 24, horizon: int = 12, n_action_steps: int = 4,
               offset: float = 0.5) -> tuple[np.ndarray, list[int]]:
    """Executed actions (steps,) and switch steps of one strategy on :class:`DisagreeingChunks`.

    ``strategy``: "synchronous", "naive async" or "ensemble" (m = 0, uniform average).
    """
    kinds = {"synchronous": (Synchronous, {}), "naive async": (AsyncChunking, {}),
             "ensemble": (DelayedEnsemble, {"ensemble_decay": 0.0})}
    if strategy not in kinds:
        raise ValueError(f"strategy must be one of {sorted(kinds)}, got {strategy!r}")
    cls, kwargs = kinds[strategy]
    ex = cls(DisagreeingChunks(horizon, offset), n_obs_steps=1, n_action_steps=n_action_steps, delay=delay, **kwargs)
    ex.reset(np.zeros((1, 1)))
    actions = [float(np.asarray(ex.act(np.full((1, 1), float(t))))[0, 0]) for t in range(steps)]
    return np.asarray(actions), list(ex.switches)


def delay_scrubber(max_delay: int = 8, steps: int = 24, horizon: int = 12, n_action_steps: int = 4) -> FigureScrubber:
    """A slider for d (0..max_delay) redrawing the three strategies' executed actions in place."""
    import ipywidgets as widgets

    if not 0 <= max_delay < horizon:
        raise ValueError(f"max_delay must be in [0, Tp={horizon}), got {max_delay!r}")
    slider = widgets.IntSlider(value=2, min=0, max=max_delay, description="d (steps)", continuous_update=True)

    def draw(fig: Figure, d: int) -> None:
        axes = fig.subplots(1, 3, sharey=True)
        t = np.arange(steps)
        for ax, name in zip(axes, ("synchronous", "naive async", "ensemble")):
            acts, switches = play_delay(name, d, steps, horizon, n_action_steps)
            ax.plot(t, t, color="0.7", lw=1, label="ideal x(t) = t")
            ax.step(t, acts, where="post", color="C0", label="executed")
            for s in switches[1:]:
                ax.axvline(s, color="C3", lw=0.6, ls=":")
            jump = np.abs(np.diff(acts)).max() if steps > 1 else 0.0
            ax.set(title=f"{name}\nlargest step {jump:.1f}", xlabel="control step t")
        axes[0].set_ylabel("action")
        axes[0].legend(fontsize=7, loc="upper left")
        fig.suptitle(f"Ta = {n_action_steps}, Tp = {horizon}, d = {d}: red dotted lines = a new chunk takes over",
                     fontsize=9)

    return FigureScrubber(draw, {"d": slider}, figsize=(9.0, 3.2))
