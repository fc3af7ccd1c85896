"""``load_exercise``: import the student's (or the worked solution's) module for one exercise."""

from __future__ import annotations

import importlib.util
import os
import sys
from types import ModuleType

from coursekit.grading.paths import exercise_dir
from coursekit.grading.registry import get_exercise


def load_exercise(exercise_id: str, directory: str | os.PathLike | None = None) -> ModuleType:
    """Import ``<folder>/<exercise_id>.py`` afresh and return it.

    The folder is ``directory`` if given, else chosen by $COURSEKIT_EXERCISES ("exercises",
    the default, "solutions", or a path; see :func:`coursekit.grading.paths.exercise_dir`).
    Every call re-executes the file, so edits show up without restarting the notebook kernel.
    Notebooks pass the functions/classes of the returned module explicitly into the library.
    """
    exercise = get_exercise(exercise_id)
    folder = exercise_dir(directory)
    path = folder / f"{exercise.id}.py"
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: expected the module for exercise {exercise.id!r} there")
    # a readable, folder-specific name: tracebacks say e.g. "exercises_chunk_windows"
    tag = "".join(c if c.isalnum() else "_" for c in folder.name) or "student"
    name = f"{tag}_{exercise.id}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise FileNotFoundError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and pickling look classes up by module name
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module
