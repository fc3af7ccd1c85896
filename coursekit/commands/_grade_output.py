"""What proves a folder is a grade output `coursekit grade` wrote: a record of every file's SHA-256.

``coursekit grade SUBMISSIONS --out DIR`` grades into a staging folder, then writes
``DIR/.coursekit-grade.json``::

    {"format": "coursekit-grade-output", "format_version": 1,
     "files": {"grades.csv": "<sha256>", "alice/feedback.md": "<sha256>", "alice/results.json": "<sha256>"}}

and swaps the folder in. A later ``--overwrite`` replaces DIR only if every entry in it is that
record or a regular file it lists, unchanged: a user's own ``grades.csv``, a results.json a student
submitted, or a file edited since grading is never replaced (the refusal names it).
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from pathlib import Path

RECORD = ".coursekit-grade.json"
FORMAT = "coursekit-grade-output"
FORMAT_VERSION = 1


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _entries(folder: Path, prefix: str = ""):
    """(relative name, lstat) of everything under ``folder``, links never followed, sorted."""
    for entry in sorted(folder.iterdir()):
        st = os.lstat(entry)
        yield prefix + entry.name, st
        if stat.S_ISDIR(st.st_mode):
            yield from _entries(entry, f"{prefix}{entry.name}/")


def write_record(folder: Path) -> None:
    """Write :data:`RECORD` into ``folder``, listing the SHA-256 of every file in it (deterministic)."""
    files = {name: _sha256(folder / name) for name, st in _entries(folder) if stat.S_ISREG(st.st_mode)}
    record = {"format": FORMAT, "format_version": FORMAT_VERSION, "files": files}
    (folder / RECORD).write_text(json.dumps(record, indent=1, sort_keys=True) + "\n", encoding="utf-8")


def grade_output_foreign(folder: Path) -> str | None:
    """None if ``folder`` is, unchanged, a grade output coursekit wrote; else which entry is not (for check_output)."""
    record_path = folder / RECORD
    try:
        if not stat.S_ISREG(os.lstat(record_path).st_mode):
            raise OSError
        record = json.loads(record_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return f"it has no readable {RECORD}, the record coursekit writes with every grade output"
    files = record.get("files") if isinstance(record, dict) and record.get("format") == FORMAT else None
    if not isinstance(files, dict):
        return f"its {RECORD} is not coursekit's record"
    holders = {str(Path(name).parent) for name in files} | {"."}
    for name, st in _entries(folder):
        if name == RECORD:
            continue
        if stat.S_ISDIR(st.st_mode):
            if not any(h == name or h.startswith(name + "/") for h in holders):
                return f"it holds the folder {name!r}, which coursekit did not write"
            continue
        if name not in files:
            return f"it holds {name!r}, which coursekit did not write"
        if not stat.S_ISREG(st.st_mode):
            return f"its {name!r} is not a regular file"
        if _sha256(folder / name) != files[name]:
            return f"its {name!r} changed since coursekit wrote it"
    return None


def grade_inputs(submissions: Path, hidden_tests: Path | None) -> list[Path]:
    """What --out must stay clear of: the submissions folder, every student folder (where a link
    points), the hidden tests. Raises FileNotFoundError / NotADirectoryError for a bad submissions folder."""
    if not submissions.exists():
        raise FileNotFoundError(f"submissions folder {str(submissions)!r} does not exist")
    if not submissions.is_dir():
        raise NotADirectoryError(f"submissions folder {str(submissions)!r} is not a folder")
    linked = [Path(os.path.realpath(p)) for p in sorted(submissions.iterdir()) if p.is_symlink()]
    return [submissions, *linked] + ([hidden_tests] if hidden_tests is not None else [])
