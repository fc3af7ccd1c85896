"""Where the course lives on disk: the repository root and the student's exercise folder."""

from __future__ import annotations

import os
from pathlib import Path

ROOT_ENV = "COURSEKIT_ROOT"
"""Environment variable naming the repository root (optional; found automatically otherwise)."""
FOLDER_ENV = "COURSEKIT_EXERCISES"
"""Environment variable choosing the implementation: "exercises" (default), "solutions" or a path."""


def _looks_like_root(path: Path) -> bool:
    return (path / "coursekit" / "grading").is_dir() and (path / "pyproject.toml").is_file()


def repo_root() -> Path:
    """The course repository: $COURSEKIT_ROOT, else the checkout holding this package, else cwd or a parent."""
    env = os.environ.get(ROOT_ENV)
    if env:
        root = Path(env).expanduser().resolve()
        if not _looks_like_root(root):
            raise FileNotFoundError(f"{ROOT_ENV}={env!r} is not a coursekit checkout (no pyproject.toml and coursekit/grading/)")
        return root
    package_parent = Path(__file__).resolve().parents[2]  # coursekit/grading/paths.py -> repo
    candidates = [package_parent, Path.cwd(), *Path.cwd().parents]
    for candidate in candidates:
        if _looks_like_root(candidate):
            return candidate
    raise FileNotFoundError(
        "could not find the coursekit repository (a folder with pyproject.toml and coursekit/grading/); "
        f"set {ROOT_ENV}=/path/to/the/clone"
    )


def exercise_dir(directory: str | os.PathLike | None = None) -> Path:
    """The folder holding the student's modules.

    ``directory`` if given; else $COURSEKIT_EXERCISES: "exercises" (or unset) -> <root>/exercises,
    "solutions" -> <root>/solutions, anything else is taken as a path.
    """
    if directory is None:
        choice = os.environ.get(FOLDER_ENV, "").strip() or "exercises"
        directory = repo_root() / choice if choice in ("exercises", "solutions") else Path(choice)
    path = Path(directory).expanduser()
    if not path.is_dir():
        raise FileNotFoundError(f"exercise folder {str(path)!r} does not exist (run `coursekit exercises build`?)")
    return path.resolve()
