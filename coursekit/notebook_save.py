"""Save the course notebooks the way git tracks them: without outputs, so a Run All leaves git clean.

`make lab` starts JupyterLab with this pre-save hook::

    jupyter lab notebooks/ --ContentsManager.pre_save_hook=coursekit.notebook_save.strip_before_save

An open notebook keeps its outputs on screen; only the file written to disk loses them (and the
editor metadata JupyterLab adds: language_info, widget state, execution timings). The file then
equals the committed one byte for byte, so `git status` stays clean and `git pull` merges.
Why not only nbstripout's git filter (which `make setup` installs too, for commits made anyway)?
A filter hides outputs from commits and diffs, but git's status check compares file sizes first:
a notebook saved with outputs is reported modified, and a pull refuses to overwrite it.

Only course notebooks (``NN_name.ipynb``) are stripped; a notebook of your own keeps its outputs.
To keep a copy of a course notebook with outputs: File > Save Notebook As... under another name.
"""

from __future__ import annotations

import re
from typing import Any

STRIP_EXTRA_KEYS = ("metadata.language_info", "metadata.jupytext", "metadata.toc", "cell.metadata.lines_to_next_cell")
"""Keys stripped besides nbstripout's defaults; the same list as the Makefile's git filter."""
NBSTRIPOUT_DEFAULT_KEYS = ("metadata.signature", "metadata.widgets", "cell.metadata.collapsed",
                           "cell.metadata.ExecuteTime", "cell.metadata.execution", "cell.metadata.heading_collapsed",
                           "cell.metadata.hidden", "cell.metadata.scrolled")
"""nbstripout's own default extra keys (it applies them only on its command line)."""
NBSTRIP_KEYS_ALL = NBSTRIPOUT_DEFAULT_KEYS + STRIP_EXTRA_KEYS
"""Everything the filter strips besides outputs and execution counts."""
COURSE_NOTEBOOK = re.compile(r"(^|/)\d\d_[^/]*\.ipynb$")
"""API paths of course notebooks: "05_diffusion_policy_pusht.ipynb" or "notebooks/05_....ipynb"."""


def strip_notebook(nb: Any) -> Any:
    """The notebook (an nbformat node or plain dict) without outputs, counts or editor metadata."""
    import nbformat
    from nbstripout import strip_output

    node = nbformat.from_dict(nb)
    return strip_output(node, keep_output=False, keep_count=False, keep_id=True,
                        extra_keys=list(NBSTRIP_KEYS_ALL))


def strip_before_save(model: dict[str, Any], path: str = "", **_: Any) -> None:
    """jupyter_server pre-save hook: strip a course notebook's model in place (others untouched)."""
    if model.get("type") != "notebook" or not COURSE_NOTEBOOK.search(path or ""):
        return
    content = model.get("content")
    if content is None:  # a rename or a checkpoint: nothing to write
        return
    model["content"] = strip_notebook(content)
