"""The scrubber mechanism: ipywidgets controls that redraw one matplotlib figure in place.

:class:`FigureScrubber` holds the controls and an ``ipywidgets.Image`` with a PNG of a matplotlib
``Figure``; moving a control redraws the figure and replaces the image's bytes, so the picture
changes where it is (no output area is cleared and re-filled). Every chapter's scrubber in
:mod:`coursekit.viz.scrubbers` is a ``draw`` function and its controls handed to it.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from typing import Any

from matplotlib.figure import Figure

__all__ = ["FigureScrubber", "figure_png"]


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
