"""coursekit demonstrations -> a LeRobotDataset v3.0 folder, with LeRobot's own feature names.

Per frame (row t of the .npz: the state before action t)::

    feature                        PushT                          arm pair (transfer cube, insertion)
    observation.state              (2,) agent x, y                (14,) qpos: joints + normalised grippers
    observation.environment_state  (16,) the T's corners          (7,) cube / (14,) peg + socket poses
    observation.image(s.top)       the 'image' array, or PushT frames rendered with ``images=True``
    action                         (2,) pusher target             (14,) joint targets
    next.reward                    clip(coverage / 0.95, 0, 1)    reward stage 0-4 after the action
    next.success                   coverage > 0.95                stage == 4
    next.done                      True on each episode's last frame
    coursekit.<name>               every array of the .npz, in its own dtype and shape

The PushT columns follow LeRobot's conventions (``coursekit.data.lerobot_pusht``: corner order,
rewards of the next state). LeRobot's columns are float32, its policies' dtype, so they alone
would not give the float64 .npz back; the ``coursekit.*`` columns do (LeRobot's policies read
only ``observation.*`` and ``action``, so they ignore them). ``meta/coursekit.json`` records which
column holds which array and the data set's meta: ``coursekit import lerobot`` uses it to restore
the .npz exactly (:mod:`coursekit.data.lerobot_import`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from coursekit.data.episodes import EpisodeDataset
from coursekit.data.lerobot_format import Feature, Frames, write_folder
from coursekit.data.lerobot_tasks import LeRobotTask, arm_names, task_of_dataset

SIDECAR = "meta/coursekit.json"
SIDECAR_VERSION = 1
PREFIX = "coursekit."
"""Key prefix of the columns that hold the .npz arrays exactly."""


def _check_action(dataset: EpisodeDataset, task: LeRobotTask) -> np.ndarray:
    if "action" not in dataset.arrays:
        raise ValueError(f"the data set has no 'action' array (it has {sorted(dataset.arrays)})")
    action = dataset["action"]
    if action.shape[1:] != (task.action_dim,):
        raise ValueError(f"{task.name} actions have {task.action_dim} values per step; the data set's 'action' "
                         f"has per-step shape {action.shape[1:]}")
    bad = np.flatnonzero(~np.isfinite(action).all(axis=1))
    if len(bad):
        episode = int(np.searchsorted(dataset.episode_ends, bad[0], side="right"))
        raise ValueError(f"the data set's action of step {int(bad[0])} (episode {episode}) is {action[bad[0]].tolist()}: "
                         f"NaN or inf actions cannot be exported ({len(bad)} such steps)")
    return action


def _images(dataset: EpisodeDataset, task: LeRobotTask, render: bool) -> np.ndarray | None:
    if "image" in dataset.arrays:
        images = dataset["image"]
        if images.dtype != np.uint8 or images.ndim != 4 or images.shape[-1] != 3:
            raise ValueError(f"the 'image' array must be (N, H, W, 3) uint8 frames, got {images.dtype} {images.shape}")
        return images
    if not render:
        return None
    if task.name != "pusht":
        raise ValueError(f"rendering images from states is for PushT; these are {task.name} demonstrations")
    from coursekit.envs.pusht_render import PushTRenderer

    renderer = PushTRenderer(96)  # the reference 96 x 96 observation camera
    return np.stack([renderer.render(s) for s in dataset["state"]])  # (N, 96, 96, 3)


def _task_columns(dataset: EpisodeDataset, task: LeRobotTask) -> dict[str, tuple[np.ndarray, Any]]:
    """LeRobot's observation/reward columns of this task: key -> (values, names)."""
    last = np.zeros(dataset.n_steps, dtype=bool)
    last[dataset.episode_ends - 1] = True
    if task.name == "pusht":
        from coursekit.data.lerobot_pusht import KEYPOINT_NAMES, lerobot_keypoints, next_rewards

        state = dataset["state"]
        reward, success = next_rewards(state, dataset.episode_ends)
        return {"observation.state": (state[:, :2], ["agent_x", "agent_y"]),
                "observation.environment_state": (lerobot_keypoints(state), list(KEYPOINT_NAMES)),
                "next.reward": (reward, None), "next.done": (last, None), "next.success": (success, None)}
    names = arm_names(task)
    columns = {"observation.state": (dataset["qpos"], {"motors": names["motors"]})}
    if "env_state" in dataset.arrays:
        columns["observation.environment_state"] = (dataset["env_state"], {"objects": names["objects"]})
    if "stage" in dataset.arrays:  # the reward stage reached after the action
        columns["next.reward"] = (dataset["stage"].astype(np.float32), None)
        columns["next.success"] = (dataset["stage"] == 4, None)
    columns["next.done"] = (last, None)
    return columns


def _exact_column(name: str, values: np.ndarray) -> tuple[np.ndarray, Feature]:
    if values.dtype.kind not in "biuf":
        raise ValueError(f"array {name!r} has dtype {values.dtype}; the LeRobot export takes numbers and booleans")
    per_step = values.shape[1:]
    if len(per_step) > 1 or (per_step and per_step[0] < 1):
        raise ValueError(f"array {name!r} has per-step shape {per_step}; the LeRobot export takes scalars, vectors "
                         f"and an (N, H, W, 3) uint8 'image' array")
    if per_step in ((), (1,)):
        return values.reshape(len(values)), Feature(str(values.dtype), (1,))
    return values, Feature(str(values.dtype), per_step)


def lerobot_frames(dataset: EpisodeDataset, *, fps: int | None = None, task_text: str | None = None,
                   images: bool = False) -> tuple[Frames, dict[str, Any]]:
    """The frames of ``dataset`` in LeRobot's features, and the meta/coursekit.json that inverts them.

    ``fps`` (optional) must equal the task's control rate; ``task_text`` replaces the task's
    default description; ``images`` renders PushT's 96 x 96 camera frames from the states when
    the data set has no 'image' array.
    """
    task = task_of_dataset(dataset.arrays, dataset.meta)
    if fps is not None and fps != task.fps:
        raise ValueError(f"--fps {fps} is not the {task.name} control rate, {task.fps} Hz: the frames are one control "
                         f"step apart and coursekit does not resample them")
    action = _check_action(dataset, task)
    named = {**_task_columns(dataset, task), "action": (action, _action_names(task))}
    columns = {key: np.asarray(v, dtype=np.bool_ if v.dtype == bool else np.float32) for key, (v, _) in named.items()}
    features = {key: Feature(str(columns[key].dtype), columns[key].shape[1:] or (1,), names)
                for key, (_, names) in named.items()}
    pictures = _images(dataset, task, images)
    if pictures is not None:
        columns[task.image_key] = pictures
        features[task.image_key] = Feature("image", pictures.shape[1:], ["height", "width", "channel"])
    arrays = {}
    for name, values in dataset.arrays.items():
        if name == "image":
            arrays[name] = {"key": task.image_key, "shape": list(values.shape[1:])}
            continue
        columns[PREFIX + name], features[PREFIX + name] = _exact_column(name, values)
        arrays[name] = {"key": PREFIX + name, "shape": list(values.shape[1:])}
    frames = Frames(columns, features, dataset.episode_ends, task.fps, tasks=(task_text or task.description,),
                    robot_type=task.robot_type)
    sidecar = {"format": SIDECAR_VERSION, "task": task.name, "arrays": arrays, "meta": dataset.meta}
    return frames, sidecar


def _action_names(task: LeRobotTask) -> Any:
    return ["target_x", "target_y"] if task.name == "pusht" else {"motors": arm_names(task)["motors"]}


def export_lerobot(dataset: EpisodeDataset, root: str | Path, **options: Any) -> dict[str, Any]:
    """Write ``dataset`` into the empty folder ``root`` as a LeRobotDataset v3.0; returns info.json's content.

    ``options``: those of :func:`lerobot_frames`. Raises ValueError (nothing useful written) on bad input.
    """
    frames, sidecar = lerobot_frames(dataset, **options)
    info = write_folder(root, frames)
    (Path(root) / SIDECAR).write_text(json.dumps(sidecar, indent=1, sort_keys=True))
    return info


def is_lerobot_export(path: str | Path) -> bool:
    """True for a folder `coursekit export lerobot` wrote (meta/info.json and meta/coursekit.json)."""
    path = Path(path)
    return (path / "meta" / "info.json").is_file() and (path / SIDECAR).is_file()
