"""Chapter 8's scrubber: temporal ensembling's weight m on a recorded stream of ACT chunks.

ACT (Zhao et al. 2023, Sec. IV-A, Fig. 5) executes, at every step, the average of the actions that
all overlapping chunks predicted for it, weighted w_i = exp(-m i) (i = 0 for the oldest chunk).
:func:`ensemble_actions` replays a recorded chunk stream through
:class:`coursekit.execution.ensembling.TemporalEnsemble`; :func:`ensemble_scrubber` lets the
student move m (and the weighting order) and see the executed action redrawn in place.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from coursekit.viz.scrubbers.figure import FigureScrubber

__all__ = ["ensemble_actions", "ensemble_scrubber"]


def ensemble_actions(chunks: np.ndarray, m: float, newest_first: bool = False) -> np.ndarray:
    """What ``TemporalEnsemble`` executes at each step when fed a recorded chunk stream.

    Args:
        chunks: (T, k, Da) the chunk predicted at every step t (ACT: chunk[t][0] is for step t).
        m: the weight's decay, w_i = exp(-m i) (ACT: 0.01).
    Returns:
        (T, Da) executed actions. An offline replay: in a live rollout the executed actions
        would change the later chunks too.
    """
    from coursekit.execution.ensembling import TemporalEnsemble

    chunks = np.asarray(chunks, dtype=np.float64)
    if chunks.ndim != 3:
        raise ValueError(f"chunks must be (T, k, Da), got shape {chunks.shape}")
    stream = iter(chunks[:, None])  # (T, B=1, k, Da)
    ens = TemporalEnsemble(lambda _h: next(stream), n_obs_steps=1, ensemble_decay=float(m), newest_first=newest_first)
    obs = np.zeros((1, 1))
    ens.reset(obs)
    return np.array([ens.act(obs)[0] for _ in range(len(chunks))])  # (T, Da)


def ensemble_scrubber(chunks: np.ndarray, joint: int, joint_name: str = "", every: int = 10, dt: float | None = None):
    """Chapter 8: scrub the ensembling weight m (log slider) and the weighting order on a
    recorded chunk stream (T, k, Da); the figure shows every ``every``-th chunk of ``joint``
    and the action ensembling would execute."""
    import ipywidgets as widgets

    chunks = np.asarray(chunks, dtype=np.float64)
    T, k, _ = chunks.shape
    name = joint_name or f"joint {joint}"

    def draw(fig: Figure, m: float, newest_first: bool) -> None:
        ax = fig.add_subplot()
        for t in range(0, T, every):
            ax.plot(np.arange(t, t + k), chunks[t, :, joint], color="0.75", lw=0.7)
        ax.plot(chunks[:, 0, joint], color="tab:blue", lw=1, ls="--", label="newest chunk's first action (m -> inf, newest first)")
        executed = ensemble_actions(chunks, m, newest_first)[:, joint]
        ax.plot(executed, "k", lw=2, label=f"executed, m = {m:.3g} ({'newest' if newest_first else 'oldest'} first)")
        ax.set(xlabel="control step", ylabel=name, xlim=(0, T + k), title=f"temporal ensembling of k = {k} chunks: {name}")
        ax.legend(fontsize=8, loc="upper right")

    controls = {
        "m": widgets.FloatLogSlider(value=0.01, base=10, min=-3, max=1, step=0.1, description="m",
                                    continuous_update=False),
        "newest_first": widgets.Checkbox(value=False, description="newest first"),
    }
    return FigureScrubber(draw, controls, figsize=(9.0, 3.4))
