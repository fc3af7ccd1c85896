"""Scrub instead of re-running cells: sliders that redraw one figure in place.

:class:`FigureScrubber` is the one mechanism: ipywidgets controls and an ``ipywidgets.Image``
holding a PNG of a matplotlib ``Figure``; moving a control redraws the figure and replaces the
image's bytes, so the picture changes where it is (no output area is cleared and re-filled).
The builders below are the course's scrubbers:

    ensemble_scrubber   chapter 8: the ensembling weight m on a recorded chunk stream
    cvae_scrubber       chapter 7: beta and the latent z of the CVAE, decoded chunk in place
    chunk_replay        chapter 5: Ta / Tp on a recorded rollout (``coursekit.viz.widgets_chunks``)

Widgets need a live kernel; in a static render the first picture shows.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

__all__ = ["FigureScrubber", "cvae_scrubber", "ensemble_scrubber", "figure_png"]


def figure_png(fig: Figure, dpi: int = 90) -> bytes:
    """PNG bytes of a matplotlib figure (Agg, no pyplot state)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


class FigureScrubber:
    """Controls + one figure redrawn in place.

    Args:
        draw: ``draw(fig, **values)`` fills a fresh ``Figure`` for the controls' current values.
        controls: name -> ipywidgets control (its ``.value`` is passed to ``draw`` as ``name``).
        figsize: figure size in inches; dpi: PNG resolution.

    ``.widget`` is the box to display (the object displays itself as the last expression of a
    cell); ``.image.value`` holds the current PNG; ``.redraws`` counts redraws.
    """

    def __init__(self, draw: Callable[..., Any], controls: dict[str, Any], figsize: tuple[float, float] = (6.0, 4.0),
                 dpi: int = 90):
        import ipywidgets as widgets

        if not controls:
            raise ValueError("controls must name at least one ipywidgets control")
        self.draw, self.controls, self.figsize, self.dpi = draw, dict(controls), figsize, dpi
        self.image = widgets.Image(format="png", layout=widgets.Layout(max_width="100%"))
        self.image.add_class("ck-scrub-figure")
        self.redraws = 0
        for control in self.controls.values():
            control.observe(self.update, names="value")
        bar = widgets.HBox(list(self.controls.values()), layout=widgets.Layout(flex_flow="row wrap"))
        self.widget = widgets.VBox([bar, self.image])
        self.widget.add_class("ck-scrubber")
        self.update()

    @property
    def values(self) -> dict[str, Any]:
        return {name: control.value for name, control in self.controls.items()}

    def update(self, *_: Any) -> None:
        """Redraw the figure for the current values and swap the image's bytes."""
        fig = Figure(figsize=self.figsize, layout="constrained")
        self.draw(fig, **self.values)
        self.image.value = figure_png(fig, self.dpi)
        self.redraws += 1

    def _repr_mimebundle_(self, **kwargs: Any) -> Any:
        return self.widget._repr_mimebundle_(**kwargs)


# --------------------------------------------------------------------------------------------
# Chapter 8: temporal ensembling's weight m
# --------------------------------------------------------------------------------------------
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
        ax.legend(fontsize=7, loc="upper right")

    controls = {
        "m": widgets.FloatLogSlider(value=0.01, base=10, min=-3, max=1, step=0.1, description="m",
                                    continuous_update=False),
        "newest_first": widgets.Checkbox(value=False, description="newest first"),
    }
    return FigureScrubber(draw, controls, figsize=(9.0, 3.4))


# --------------------------------------------------------------------------------------------
# Chapter 7: beta and z of the CVAE
# --------------------------------------------------------------------------------------------
def cvae_scrubber(models: dict[float, Any], posterior: Callable[[Any], tuple[Any, Any]],
                  modes: Sequence[np.ndarray] = (), z_range: float = 3.0):
    """Chapter 7: pick beta (one trained toy CVAE per value) and move the latent z along the
    model's most-used dimension (the others stay 0, the prior's mean) and the observation o;
    the decoded chunk is redrawn in place, over the prior's spread.

    Args:
        models: beta -> trained ``ACTPolicy`` with Do = Da = 1.
        posterior: policy -> (mu, logvar) (n, d) of held-out demonstrations (picks the dimension).
        modes: optional (K,) curves drawn dotted for reference (the true modes at o = 0).
    """
    import ipywidgets as widgets
    import torch

    from coursekit.nn.kl import gaussian_kl_per_dim

    used = {}
    for beta, policy in models.items():
        mu, logvar = posterior(policy)
        used[beta] = int(torch.argmax(gaussian_kl_per_dim(mu, logvar)))

    def draw(fig: Figure, beta: float, z: float, o: float) -> None:
        policy = models[beta]
        d = policy.config.latent_dim
        ax = fig.add_subplot()
        with torch.no_grad():
            o_n = policy.normalizers["obs"].normalize(torch.full((9, 1), float(o)))
            zs = torch.zeros(9, d)
            zs[:, used[beta]] = torch.linspace(-2, 2, 9)
            spread = policy.normalizers["action"].unnormalize(policy.decode(o_n, zs))[..., 0].numpy()  # (9, K)
            one = torch.zeros(1, d)
            one[0, used[beta]] = float(z)
            chunk = policy.normalizers["action"].unnormalize(policy.decode(o_n[:1], one))[0, :, 0].numpy()  # (K,)
        j = np.arange(1, chunk.shape[0] + 1)
        for s in spread:
            ax.plot(j, s, color="0.8", lw=1)
        for curve in modes:
            ax.plot(j, float(o) + np.asarray(curve), ":", color="tab:red", lw=1)
        ax.plot(j, chunk, "k-o", lw=2, ms=3, label=f"decoded at z[{used[beta]}] = {z:+.2f}")
        ax.set(xlabel="step j", ylabel="action", ylim=(-2.1, 2.1),
               title=f"beta = {beta}: grey = z[{used[beta]}] from -2 to 2 (prior's range), others 0")
        ax.legend(fontsize=8, loc="lower left")

    betas = sorted(models)
    controls = {
        "beta": widgets.SelectionSlider(options=betas, value=betas[len(betas) // 2], description="beta"),
        "z": widgets.FloatSlider(value=0.0, min=-z_range, max=z_range, step=0.1, description="z"),
        "o": widgets.FloatSlider(value=0.0, min=-1.0, max=1.0, step=0.1, description="o"),
    }
    return FigureScrubber(draw, controls, figsize=(6.5, 3.6))
