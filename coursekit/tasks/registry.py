"""THE task registry: every task by name, its command-line aliases, its gymnasium id.

    get_task("pusht").control_hz         # 10.0
    get_task("aloha-cube").name          # 'transfer_cube' (an alias)
    register_task(Task(name="reach", ...))   # a new task: collect, train, eval and replays take it

``TASKS`` holds the course's tasks; :func:`register_task` adds one (and registers its gymnasium
id, as ``gymnasium.register`` does for envs). Nothing else in the library keeps a table of tasks.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from coursekit.tasks.aloha import INSERTION, TRANSFER_CUBE
from coursekit.tasks.pusht import PUSHT
from coursekit.tasks.record import Task

TASKS: dict[str, Task] = {task.name: task for task in (PUSHT, TRANSFER_CUBE, INSERTION)}
"""Canonical name -> :class:`Task`; :func:`register_task` adds to it."""


def _by_name() -> dict[str, Task]:
    """Every accepted name (canonical names and aliases) -> its task."""
    return {name: task for task in TASKS.values() for name in task.names}


def get_task(name: str) -> Task:
    """The task called ``name`` (its canonical name or an alias)."""
    table = _by_name()
    if not isinstance(name, str) or name not in table:
        raise ValueError(f"unknown task {name!r}; expected one of {sorted(table)}")
    return table[name]


def task_names(aliases: bool = False) -> list[str]:
    """Canonical names in registration order (with ``aliases``: every accepted name, sorted)."""
    return sorted(_by_name()) if aliases else list(TASKS)


def task_in_meta(meta: Mapping[str, Any] | None) -> Task | None:
    """The task a dataset's meta names: its "task" (a name) or its "env_id" (a gymnasium id); None if neither."""
    meta = meta or {}
    env_id = meta.get("env_id")  # get_task checks "task"; meta comes from a file a user can edit
    if env_id is not None and not isinstance(env_id, str):
        raise ValueError(f"the dataset's 'env_id' is {env_id!r}: expected a gymnasium id such as "
                         f"{TASKS[task_names()[0]].gym_id!r}")
    if meta.get("task") is not None:
        return get_task(meta["task"])
    by_gym_id = {task.gym_id: task for task in TASKS.values()}
    return by_gym_id.get(env_id)


def register_gym_env(task: Task) -> None:
    """Register ``task.gym_id`` with gymnasium (idempotent; the env itself enforces the episode length)."""
    import gymnasium

    if task.gym_id not in gymnasium.registry:
        gymnasium.register(id=task.gym_id, entry_point=task.env, disable_env_checker=True)


def register_gym_envs() -> None:
    """Register every task's gymnasium id (cheap: entry points are strings, no simulator is imported)."""
    for task in TASKS.values():
        register_gym_env(task)


def register_task(task: Task) -> Task:
    """Add ``task`` to the registry and register its gymnasium id; refuses a name or gym id already taken."""
    if not isinstance(task, Task):
        raise ValueError(f"register_task takes a coursekit.tasks.Task, got {type(task).__name__}")
    taken = sorted(set(task.names) & set(_by_name()))
    if taken:
        raise ValueError(f"task name(s) {taken} are already registered; unregister_task first or choose another name")
    if any(t.gym_id == task.gym_id for t in TASKS.values()):
        raise ValueError(f"gym id {task.gym_id!r} already belongs to a registered task")
    TASKS[task.name] = task
    register_gym_env(task)
    return task


def unregister_task(name: str) -> Task:
    """Remove a task added by :func:`register_task` (and its gymnasium id); returns it."""
    import gymnasium

    task = get_task(name)
    del TASKS[task.name]
    gymnasium.registry.pop(task.gym_id, None)
    return task
