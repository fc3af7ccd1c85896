"""Every task a policy can be evaluated on, by name: one adapter per task."""

from __future__ import annotations

from typing import Any

TASKS = ("pusht", "transfer_cube", "insertion")
"""Task names (a policy's features name its world; an arm-pair dataset's meta names its task)."""


def make_adapter(task: str, policy: Any) -> Any:
    """The :class:`~coursekit.evaluate.closed_loop.TaskAdapter` of ``task`` for ``policy``."""
    if task == "pusht":
        from coursekit.evaluate.pusht import PushTAdapter

        return PushTAdapter(policy)
    if task in ("transfer_cube", "insertion"):
        from coursekit.evaluate.aloha import ArmPairAdapter

        return ArmPairAdapter(policy, task)
    raise ValueError(f"unknown task {task!r}; expected one of {list(TASKS)}")


def task_of(policy: Any, dataset_meta: dict[str, Any] | None) -> str:
    """The task a policy was trained for: PushT from its features, the arm-pair task from its data's meta."""
    from coursekit.data.features import get_features

    world = get_features(policy.config.features).task
    if world == "pusht":
        return "pusht"
    task = (dataset_meta or {}).get("task")
    if task not in TASKS or task == "pusht":
        raise ValueError(f"the policy uses arm-pair features but its dataset meta names task {task!r}; "
                         f"expected one of {[t for t in TASKS if t != 'pusht']}")
    return task
