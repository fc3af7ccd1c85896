"""Tasks: one record per task, the single home of its facts, and the one registry.

    record.py    Task (name, aliases, gym id, env, control rate, episode length, default features,
                 expert, evaluation figures, replay drawing) and ReplayDrawing
    pusht.py     PUSHT
    aloha.py     TRANSFER_CUBE, INSERTION (the arm pair's shared rate, episode length, recorded state)
    registry.py  TASKS, get_task (names and aliases), register_task, the gymnasium ids

Every other module reads a task's facts from here: the envs their rate and episode length, the
experts their episode length and ids, evaluation its protocol, the delay model its control
period, the replays their drawing, ``coursekit collect`` its names and experts. The records are
plain data with entry points ("module:attribute") for code in higher layers, so this package
imports no other coursekit layer and no simulator. A new task = its env module + its record
(``register_task``) + its expert.
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "Task": "coursekit.tasks.record",
    "ReplayDrawing": "coursekit.tasks.record",
    "TASKS": "coursekit.tasks.registry",
    "get_task": "coursekit.tasks.registry",
    "task_names": "coursekit.tasks.registry",
    "task_in_meta": "coursekit.tasks.registry",
    "register_task": "coursekit.tasks.registry",
    "unregister_task": "coursekit.tasks.registry",
    "PUSHT": "coursekit.tasks.pusht",
    "TRANSFER_CUBE": "coursekit.tasks.aloha",
    "INSERTION": "coursekit.tasks.aloha",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)
