"""How each coursekit task appears in LeRobot's format: rate, task text, robot type, labels.

The control rate and gym id are read from the task's record (``coursekit.tasks``), never
copied: a LeRobot set's ``fps`` must equal the rate (10 for PushT, 50 for the arm pair), since a
policy's chunk of Tp actions means Tp control periods. The rest is how LeRobot's own PushT and
ALOHA sets label things (``lerobot/pusht_keypoints``, ``lerobot/aloha_sim_*_human``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from coursekit.tasks.aloha import INSERTION, TRANSFER_CUBE
from coursekit.tasks.registry import get_task as task_record


@dataclass(frozen=True)
class LeRobotTask:
    """One coursekit task as a LeRobot data set."""

    name: str
    """coursekit's task name ('pusht', 'transfer_cube', 'insertion')."""
    description: str
    """Default task text of meta/tasks.parquet (``coursekit export lerobot --task`` replaces it)."""
    robot_type: str | None
    """info.json's robot_type (LeRobot's ALOHA sets say 'aloha'; its PushT sets give none)."""
    image_key: str
    """The camera feature's key in LeRobot's own set of this task."""
    action_dim: int
    """Length of one action (2: PushT target; 14: the arm pair's joint targets)."""

    @property
    def fps(self) -> int:
        """Frames per second = the task's control rate (its record's ``control_hz``)."""
        return int(task_record(self.name).control_hz)

    @property
    def env_id(self) -> str:
        """The coursekit gymnasium id recorded in an imported data set's meta (the record's ``gym_id``)."""
        return task_record(self.name).gym_id


TASKS: dict[str, LeRobotTask] = {
    "pusht": LeRobotTask("pusht", "Push the T-shaped block onto the T-shaped target.",
                         None, "observation.image", 2),
    TRANSFER_CUBE.name: LeRobotTask(TRANSFER_CUBE.name, "Pick up the cube with the right arm and transfer it to the left arm.",
                                 "aloha", "observation.images.top", 14),
    INSERTION.name: LeRobotTask(INSERTION.name, "Pick up the socket and the peg with one arm each and insert the peg into the socket.",
                             "aloha", "observation.images.top", 14),
}
"""coursekit task name -> :class:`LeRobotTask`."""


def get_task(name: str) -> LeRobotTask:
    if name not in TASKS:
        raise ValueError(f"unknown task {name!r}; expected one of {sorted(TASKS)}")
    return TASKS[name]


def task_of_dataset(arrays: Mapping[str, Any], meta: Mapping[str, Any]) -> LeRobotTask:
    """The task of coursekit demonstrations: PushT states, or the arm pair's qpos (task from meta or env_state)."""
    if "state" in arrays:
        return TASKS["pusht"]
    if "qpos" not in arrays:
        raise ValueError(f"cannot tell the task of a data set with arrays {sorted(arrays)}: PushT data has 'state', "
                         f"the arm pair's 'qpos'")
    by_env = {t.env_id: t.name for t in TASKS.values()}
    name = meta.get("task") or by_env.get(meta.get("env_id"))
    if name is None and "env_state" in arrays:
        name = {7: TRANSFER_CUBE.name, 14: INSERTION.name}.get(arrays["env_state"].shape[-1])
    if name not in (TRANSFER_CUBE.name, INSERTION.name):
        raise ValueError(f"cannot tell which arm-pair task these demonstrations are (meta task {meta.get('task')!r}, "
                         f"env_id {meta.get('env_id')!r})")
    return TASKS[name]


def arm_names(task: LeRobotTask) -> dict[str, list[str]]:
    """LeRobot's labels for the arm pair: {"motors": [left_waist, ..., right_gripper]} and the objects' poses."""
    from coursekit.envs.aloha.model import STATE_NAMES
    from coursekit.envs.aloha.tasks import TASKS as ALOHA_TASKS

    objects = ALOHA_TASKS[task.name].objects
    return {"motors": [n.replace("/", "_") for n in STATE_NAMES],
            "objects": [f"{o}_{c}" for o in objects for c in ("x", "y", "z", "qw", "qx", "qy", "qz")]}
