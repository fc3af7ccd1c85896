"""The output policy of ``coursekit export lerobot`` and ``coursekit import lerobot``, in one place.

Both commands claim their output before reading anything (``coursekit.outputs.claim_output``:
checked, then locked for the whole run, with what killed earlier runs left beside it swept), and
write atomically: the export folder is built in a recorded staging folder and swapped into place
(``staging_dir`` + ``replace_dir``); the imported .npz is written by ``EpisodeDataset.save``
(recorded temporary file + rename) under the same lock.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from coursekit.data.episodes import dataset_foreign
from coursekit.output_lock import OutputLock
from coursekit.outputs import claim_output, replace_dir, staging_dir


def require_pyarrow() -> None:
    """LeRobot's parquet files need pyarrow (environment.txt; ``pip install coursekit[lerobot]``)."""
    try:
        import pyarrow  # noqa: F401
    except ModuleNotFoundError:
        raise ValueError("LeRobot's format needs the pyarrow package: pip install pyarrow") from None


def _export_foreign(path: Path) -> str | None:
    from coursekit.data.lerobot_export import is_lerobot_export

    if is_lerobot_export(path):
        return None
    names = sorted(p.name for p in path.iterdir())
    return f"it holds {', '.join(names[:3])}{', ...' if len(names) > 3 else ''}"



@contextlib.contextmanager
def _claimed(out: Path, **policy: Any) -> Iterator[OutputLock]:
    require_pyarrow()
    with claim_output(out, **policy) as lock:
        for leftover in lock.swept:
            print(f"removed {str(leftover)!r}, left by an interrupted earlier run", file=sys.stderr)
        yield lock


def claim_export_out(out: Path, data: Path, overwrite: bool) -> contextlib.AbstractContextManager[OutputLock]:
    """Before any work: OUT_DIR is new, empty, or (with --overwrite) an earlier export; never the input."""
    return _claimed(out, what="coursekit LeRobot export", foreign=_export_foreign, directory=True,
                    overwrite=overwrite, inputs=[data], flag="OUT_DIR")


def write_export_folder(out: Path, lock: OutputLock, write: Callable[[Path], Any]) -> Any:
    """Run ``write(folder)`` in a staging folder beside ``out``, then swap it into place; returns its result."""
    with staging_dir(out, lock) as tmp:
        result = write(tmp)
        replace_dir(tmp, out, lock)  # the old export (if any) ends up in tmp and is removed with it
    return result


def claim_import_out(out: Path, folder: Path, overwrite: bool) -> contextlib.AbstractContextManager[OutputLock]:
    """Before any work: OUT is a new .npz, or (with --overwrite) a coursekit data set; never inside the input."""
    return _claimed(out, what="coursekit dataset", foreign=dataset_foreign, directory=False, overwrite=overwrite,
                    inputs=[folder], flag="OUT")
