"""A LeRobotDataset v3.0 folder -> coursekit demonstrations (an ``EpisodeDataset`` for ``coursekit train``).

Two ways, chosen per folder:

- A folder ``coursekit export lerobot`` wrote (it has meta/coursekit.json) comes back EXACTLY:
  every array from its ``coursekit.*`` column (or the camera feature, for 'image'), the same
  dtypes, shapes, episode boundaries and meta.
- Any other v3.0 folder (a LeRobot set, or an export read with ``features=``) is mapped by
  LeRobot's conventions (:mod:`coursekit.data.lerobot_pusht` for PushT)::

      LeRobot                          PushT                         arm pair
      action                           action (N, 2)                 action (N, 14)
      observation.state                \\ state (N, 5): agent xy +    qpos (N, 14)
      observation.environment_state    /  block pose from the corners env_state (N, 7 | 14), if present
      one image feature                image (N, H, W, 3) uint8      image (N, H, W, 3) uint8

  The task is PushT for 2-d actions; for 14-d ones the objects' pose size tells transfer cube
  (7) from insertion (14), else ``as_task`` must say. An arm-pair set without object poses
  (LeRobot's aloha_sim_*_human) trains with ``--features aloha_qpos``.

Either way the folder's fps must be the task's control rate and every action must be finite.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from coursekit.data.episodes import EpisodeDataset
from coursekit.data.lerobot_export import SIDECAR, SIDECAR_VERSION
from coursekit.data.lerobot_reader import LeRobotFolder, read_folder
from coursekit.data.lerobot_tasks import TASKS, LeRobotTask, get_task
from coursekit.tasks.aloha import INSERTION, TRANSFER_CUBE

MAPPED = ("observation.state", "observation.environment_state")
"""LeRobot observation features with a coursekit counterpart (besides action and one camera)."""


def _exact(folder: LeRobotFolder, sidecar: dict[str, Any]) -> tuple[LeRobotTask, dict[str, np.ndarray], dict]:
    if sidecar.get("format") != SIDECAR_VERSION or not isinstance(sidecar.get("arrays"), dict):
        raise ValueError(f"{str(folder.root)!r}: {SIDECAR} is not a coursekit export record of format {SIDECAR_VERSION}")
    arrays = {}
    for name, where in sidecar["arrays"].items():
        values = folder.column(where["key"])
        arrays[name] = values.reshape(len(values), *where["shape"])
    return get_task(sidecar.get("task")), arrays, sidecar.get("meta") or {}


def _infer_task(folder: LeRobotFolder, as_task: str | None) -> LeRobotTask:
    if as_task is not None:
        return get_task(as_task)
    action = folder.features.get("action")
    if action is None:
        raise ValueError(f"{str(folder.root)!r} has no 'action' feature (it has {sorted(folder.features)})")
    if action.shape == (2,):
        return TASKS["pusht"]
    env = folder.features.get("observation.environment_state")
    by_objects = {7: TRANSFER_CUBE.name, 14: INSERTION.name}
    if action.shape == (14,) and env is not None and env.shape[0] in by_objects:
        return TASKS[by_objects[env.shape[0]]]
    if action.shape == (14,):
        raise ValueError(f"{str(folder.root)!r} holds 14-d arm-pair actions but no object poses to tell the task by; "
                         f"say which with --as transfer_cube or --as insertion")
    raise ValueError(f"{str(folder.root)!r} has actions of shape {list(action.shape)}: coursekit's tasks take 2 (PushT) "
                     f"or 14 (the arm pair)")


def _selection(folder: LeRobotFolder, features: Sequence[str] | None) -> tuple[list[str], list[str]]:
    """(observation features to import, video features left out)."""
    cameras = [k for k, f in folder.features.items() if f.dtype in ("image", "video")]
    if features is None:
        chosen = [k for k in folder.features if k in MAPPED or (k in cameras and folder.features[k].dtype == "image")]
        return chosen, [k for k in cameras if folder.features[k].dtype == "video"]
    for key in features:
        if key not in folder.features:
            raise ValueError(f"--features names {key!r}, which {str(folder.root)!r} does not have (it has "
                             f"{sorted(k for k in folder.features if k.startswith('observation'))})")
        if key not in MAPPED and key not in cameras and key != "action":
            raise ValueError(f"--features {key!r} has no coursekit counterpart; coursekit imports {list(MAPPED)} "
                             f"and one camera (action always)")
    return [k for k in features if k != "action"], []


def _by_convention(folder: LeRobotFolder, task: LeRobotTask, chosen: list[str]) -> dict[str, np.ndarray]:
    if "action" not in folder.features:
        raise ValueError(f"{str(folder.root)!r} has no 'action' feature (it has {sorted(folder.features)})")
    if folder.features["action"].shape != (task.action_dim,):
        raise ValueError(f"{str(folder.root)!r}: {task.name} takes {task.action_dim}-d actions; the folder's 'action' "
                         f"has shape {list(folder.features['action'].shape)}")
    arrays = {"action": folder.column("action").astype(np.float64)}
    cameras = [k for k in chosen if folder.features[k].dtype in ("image", "video")]
    if len(cameras) > 1:
        raise ValueError(f"{str(folder.root)!r} has several cameras {cameras}; choose one with --features")
    if cameras:
        arrays["image"] = folder.column(cameras[0])
    if task.name == "pusht":
        from coursekit.data.lerobot_pusht import states_from_lerobot

        missing = [k for k in MAPPED if k not in chosen]
        if missing:
            raise ValueError(f"PushT states need observation.state (the agent) and observation.environment_state (the "
                             f"T's corners, as in lerobot/pusht_keypoints); missing from the import: {missing}")
        arrays["state"] = states_from_lerobot(folder.column(MAPPED[0]), folder.column(MAPPED[1]), folder.episode_ends)
        return arrays
    if "observation.state" not in chosen:
        raise ValueError("the arm pair's qpos comes from observation.state, which is missing from the import")
    arrays["qpos"] = folder.column("observation.state").astype(np.float64)
    if "observation.environment_state" in chosen:
        arrays["env_state"] = folder.column("observation.environment_state").astype(np.float64)
    return arrays


def _check_actions(root: Path, action: np.ndarray, ends: np.ndarray) -> None:
    bad = np.flatnonzero(~np.isfinite(action.reshape(len(action), -1)).all(axis=1))
    if len(bad):
        episode = int(np.searchsorted(ends, bad[0], side="right"))
        raise ValueError(f"LeRobot folder {str(root)!r}: the action of frame {int(bad[0])} (episode {episode}) is "
                         f"{action[bad[0]].tolist()}; NaN or inf actions cannot be trained on ({len(bad)} such frames)")


def import_lerobot(root: str | Path, features: Sequence[str] | None = None,
                   as_task: str | None = None) -> tuple[EpisodeDataset, list[str]]:
    """Read a LeRobotDataset v3.0 folder as coursekit demonstrations; returns (data set, notes for the user).

    ``features``: the LeRobot features to import (forces the convention mapping even for a
    coursekit export); ``as_task``: the coursekit task when the folder cannot tell it.
    """
    root = Path(root)
    folder = read_folder(root)
    notes: list[str] = []
    if (root / SIDECAR).is_file() and features is None and as_task is None:
        try:
            sidecar = json.loads((root / SIDECAR).read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{str(root)!r}: {SIDECAR} is not valid JSON ({exc})") from None
        task, arrays, meta = _exact(folder, sidecar if isinstance(sidecar, dict) else {})
    else:
        task = _infer_task(folder, as_task)
        chosen, skipped = _selection(folder, features)
        notes += [f"left out {k}: it is mp4 video, and coursekit reads parquet frames and image features" for k in skipped]
        arrays = _by_convention(folder, task, chosen)
        meta = {"env_id": task.env_id, "task": task.name, "obs_type": "state", "control_hz": folder.fps,
                "source": {"lerobot_folder": str(root), "features": ["action", *chosen], "tasks": list(folder.tasks),
                           "robot_type": folder.info.get("robot_type"), "codebase_version": folder.info["codebase_version"]}}
        if task.name == "pusht":
            meta["state_columns"] = ["agent_x", "agent_y", "block_x", "block_y", "block_angle_unwrapped"]
        elif "env_state" not in arrays:
            notes.append("no object poses (observation.environment_state): train with --features aloha_qpos")
    if folder.fps != task.fps:
        raise ValueError(f"LeRobot folder {str(root)!r} runs at {folder.fps} fps, but {task.name} is controlled at "
                         f"{task.fps} Hz: coursekit does not resample demonstrations")
    if "action" not in arrays:
        raise ValueError(f"LeRobot folder {str(root)!r} gives no 'action' array")
    _check_actions(root, arrays["action"], folder.episode_ends)
    return EpisodeDataset(arrays=arrays, episode_ends=folder.episode_ends, meta=dict(meta)), notes
