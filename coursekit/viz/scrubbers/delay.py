"""Chapter 11's scrubber: the inference delay d, on a stream of chunks that disagree.

A hand-built predictor stands in for the policy, so every executed action can be read off. The
observation is the robot's position (a position-controlled robot is where its last action sent
it), and each chunk is planned FROM that position, as a policy plans from what it sees: the
chunk requested at position p moves one step at a time at its own speed, p + (j + 1) v_k, with
speeds that alternate 1 + s, 1 - s, 1 + s, ... (s = ``spread``): consecutive chunks agree on
where the robot is but not on how fast to go on, as two samples of a generative head may not.
Moving d redraws, in place, what each strategy of :mod:`coursekit.execution.delay` executes:

- synchronous: flat steps while it waits (it falls behind the on-time line, one unit per step)
  and NO jump: the new chunk was planned from where the robot stands;
- naive async: never waits, but jumps at each switch: the new chunk was planned from where the
  robot was d steps earlier, and the robot has since moved at the old chunk's speed, so its
  first executed action lands about 2 d s away from the old course;
- ensemble (m = 0): the average of the arrived chunks covering each step. Once 2 d >= Tp a
  chunk has run out before the next one arrives (requested d steps later, it arrives after d
  more), so there is only ever one chunk to average and the panel equals naive async.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from coursekit.execution.delay import AsyncChunking, DelayedEnsemble, Synchronous
from coursekit.viz.scrubbers.figure import FigureScrubber

__all__ = ["DisagreeingChunks", "delay_scrubber", "play_delay"]


class DisagreeingChunks:
    """Predictor (B, To, 1) positions -> (B, Tp, 1): chunk k from position p is p + (j + 1) (1 + (-1)^k s).

    Index j is the action for step r + j (r: the step of the request); the newest observation
    is the robot's position p when the chunk was requested.
    """

    def __init__(self, horizon: int = 12, spread: float = 0.25):
        if horizon < 1:
            raise ValueError(f"horizon (Tp) must be >= 1, got {horizon!r}")
        if not 0 <= spread < 1:
            raise ValueError(f"spread must be in [0, 1) (speeds 1 +- spread stay forward), got {spread!r}")
        self.horizon, self.spread, self.calls = int(horizon), float(spread), 0

    def __call__(self, obs_history: np.ndarray) -> np.ndarray:
        p = np.asarray(obs_history, dtype=np.float64)[:, -1, 0]  # (B,) position at the request
        speed = 1.0 + (self.spread if self.calls % 2 == 0 else -self.spread)
        self.calls += 1
        chunk = p[:, None] + speed * np.arange(1, self.horizon + 1)[None, :]  # (B, Tp)
        return chunk[:, :, None]  # (B, Tp, 1)


def play_delay(strategy: str, delay: int, steps: int = 24, horizon: int = 12, n_action_steps: int = 4,
               spread: float = 0.25) -> tuple[np.ndarray, list[int]]:
    """Executed actions (steps,) and switch steps of one strategy on :class:`DisagreeingChunks`.

    ``strategy``: "synchronous", "naive async" or "ensemble" (m = 0, uniform average). The
    observation at step t is the position after step t - 1 (0 at the start).
    """
    kinds = {"synchronous": (Synchronous, {}), "naive async": (AsyncChunking, {}),
             "ensemble": (DelayedEnsemble, {"ensemble_decay": 0.0})}
    if strategy not in kinds:
        raise ValueError(f"strategy must be one of {sorted(kinds)}, got {strategy!r}")
    cls, kwargs = kinds[strategy]
    ex = cls(DisagreeingChunks(horizon, spread), n_obs_steps=1, n_action_steps=n_action_steps, delay=delay, **kwargs)
    position = np.zeros((1, 1))
    ex.reset(position)
    actions = []
    for _ in range(steps):
        position = np.asarray(ex.act(position), dtype=np.float64).reshape(1, 1)  # the robot goes where it is sent
        actions.append(float(position[0, 0]))
    return np.asarray(actions), list(ex.switches)


def delay_scrubber(max_delay: int = 8, steps: int = 24, horizon: int = 12, n_action_steps: int = 4,
                   spread: float = 0.25) -> FigureScrubber:
    """A slider for d (0..max_delay) redrawing the three strategies' executed actions in place."""
    import ipywidgets as widgets

    if not 0 <= max_delay < horizon:
        raise ValueError(f"max_delay must be in [0, Tp={horizon}), got {max_delay!r}")
    slider = widgets.IntSlider(value=2, min=0, max=max_delay, description="d (steps)", continuous_update=True)

    def draw(fig: Figure, d: int) -> None:
        axes = fig.subplots(1, 3, sharey=True)
        t = np.arange(steps)
        for ax, name in zip(axes, ("synchronous", "naive async", "ensemble")):
            acts, switches = play_delay(name, d, steps, horizon, n_action_steps, spread)
            ax.plot(t, t + 1.0, color="0.7", lw=1, label="1 per step (on time)")
            ax.step(t, acts, where="post", color="C0", label="executed")
            for s in switches[1:]:
                ax.axvline(s, color="C3", lw=0.6, ls=":")
            step = np.diff(np.concatenate([[0.0], acts]))  # (steps,) what each step moved
            held = int((step == 0).sum())
            ax.set(title=f"{name}\nlargest step {np.abs(step).max():.2f}, {held} step{'' if held == 1 else 's'} held\n"
                         f"ends at {acts[-1]:.1f} (1 per step: {steps:d})", xlabel="control step t")
            ax.title.set_fontsize(9)
        axes[0].set_ylabel("position (= last action)")
        axes[0].legend(fontsize=8, loc="upper left")
        fig.suptitle(f"Ta = {n_action_steps}, Tp = {horizon}, d = {d}, chunk speeds {1 + spread:g} / {1 - spread:g} in turn: "
                     "red dotted lines = a new chunk takes over", fontsize=9)

    return FigureScrubber(draw, {"d": slider}, figsize=(9.5, 3.9))
