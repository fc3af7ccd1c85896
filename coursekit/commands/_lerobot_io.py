"""The output policy of ``coursekit export lerobot`` and ``coursekit import lerobot``, in one place.

Both commands check their output before reading anything (``coursekit.outputs.check_output``),
remove what killed earlier runs left beside it, and write atomically: the export folder is built
in a hidden staging folder and swapped into place (``staging_dir`` + ``replace_dir``); the
imported .npz is written by ``EpisodeDataset.save`` (temporary file + rename).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from coursekit.outputs import check_output, clean_leftovers, replace_dir, staging_dir


def require_pyarrow() -> None:
    """LeRobot's parquet files need pyarrow (environment.txt; ``pip install coursekit[lerobot]``)."""
    try:
        import pyarrow  # noqa: F401
    except ModuleNotFoundError:
        raise ValueError("LeRobot's format needs the pyarrow package: pip install pyarrow") from None


def _clean(out: Path) -> None:
    for leftover in clean_leftovers(out):
        print(f"removed {str(leftover)!r}, left by an interrupted earlier run", file=sys.stderr)


def check_export_out(out: Path, data: Path, overwrite: bool) -> None:
    """Before any work: OUT_DIR is new, empty, or (with --overwrite) an earlier export; never the input."""
    require_pyarrow()
    from coursekit.data.lerobot_export import is_lerobot_export

    check_output(out, what="coursekit LeRobot export", is_ours=is_lerobot_export, directory=True,
                 overwrite=overwrite, inputs=[data], flag="OUT_DIR")


def write_export_folder(out: Path, write: Callable[[Path], Any]) -> Any:
    """Run ``write(folder)`` in a staging folder beside ``out``, then swap it into place; returns its result."""
    _clean(out)
    with staging_dir(out) as tmp:
        result = write(tmp)
        replace_dir(tmp, out)  # the old export (if any) ends up in tmp and is removed with it
    return result


def check_import_out(out: Path, folder: Path, overwrite: bool) -> None:
    """Before any work: OUT is a new .npz, or (with --overwrite) a coursekit data set; never inside the input."""
    require_pyarrow()
    from coursekit.data.episodes import is_dataset_file

    check_output(out, what="coursekit dataset", is_ours=is_dataset_file, directory=False, overwrite=overwrite,
                 inputs=[folder], flag="OUT")
    _clean(out)
