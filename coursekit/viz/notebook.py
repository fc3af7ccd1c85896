"""Show an exported meshcat page inside a notebook: an iframe whose ``srcdoc`` IS the page.

The page is embedded whole (about 0.9 MB plus the animation), so the cell keeps working after
the kernel (and its meshcat server) is gone, offline, in a saved notebook, and on a machine that
cannot reach the kernel's ports. ``Visualizer.jupyter_cell()`` would instead embed the live
server's URL: a dead frame once the kernel stops.
"""

from __future__ import annotations

import html as html_lib
import os
from pathlib import Path


def iframe_html(page: str, height: int = 480) -> str:
    """The ``<iframe srcdoc=...>`` markup that displays the HTML document ``page`` (a string)."""
    if not isinstance(page, str) or "<html" not in page.lower():
        raise ValueError(f"page must be an HTML document string, got {type(page).__name__} "
                         f"starting {str(page)[:60]!r}")
    if height < 50:
        raise ValueError(f"height must be at least 50 pixels, got {height}")
    srcdoc = html_lib.escape(page, quote=True)  # & < > " ' escaped: the page survives as one attribute
    return (f'<div style="width: 100%; height: {int(height)}px; resize: vertical; overflow: hidden">'
            f'<iframe srcdoc="{srcdoc}" style="width: 100%; height: 100%; border: none"></iframe></div>')


def show_html(page_or_path: str | os.PathLike, height: int = 480):
    """An ``IPython.display.HTML`` that shows an exported meshcat page inline (works offline).

    Args:
        page_or_path: the HTML text (``viewer.html()``) or the path of a saved ``.html`` file.
        height: iframe height in pixels.

    Returns:
        ``IPython.display.HTML``: make it the last expression of a cell, or ``display()`` it.
    """
    from IPython.display import HTML  # notebooks only: keep IPython out of library imports

    if isinstance(page_or_path, Path) or (isinstance(page_or_path, str) and "<" not in page_or_path):
        path = Path(page_or_path)
        if not path.is_file():
            raise FileNotFoundError(f"no HTML file at {path}")
        page = path.read_text(encoding="utf-8")
    else:
        page = os.fspath(page_or_path)
    return HTML(iframe_html(page, height))
