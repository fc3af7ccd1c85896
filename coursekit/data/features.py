"""Policy input features: what the network sees of the world, for every task, in ONE table.

A policy stores the NAME of its features in its config (``config.features``); the same name
turns demonstrations into training arrays and live environment observations into policy
inputs, so training and evaluation can never disagree. Every policy type accepts every entry::

    name             task    reads                   per step (Do)
    pusht_state      pusht   state (5)               [agent_x, agent_y, block_x, block_y, sin angle, cos angle]  (6)
    pusht_keypoints  pusht   state (5)               [agent_x, agent_y, kp0_x, kp0_y, ..., kp{K-1}_x, kp{K-1}_y]  (2 + 2K)
    pusht_image      pusht   state (5) -> image      a 96x96 camera image + agent_pos (2) (obs_type "image")
    aloha_state      aloha   qpos (14), env_state    [qpos (14), env_state (7 cube | 14 peg + socket)]  (21 or 28)
    aloha_qpos       aloha   qpos (14)               qpos only: proprioception (cannot see where the object is)
    raw_state        any     state (D)               the observation vector as it is (a task observing one vector)

PushT: the simulator never wraps the block angle (demonstrations show it from about -19 to +13
rad), so a raw angle must never be min-max scaled: two identical poses would get different
inputs and the [-1, 1] range would be dominated by a few spinning episodes. Orientation is
therefore encoded as (sin, cos), which is continuous and identical for angle and angle + 2 pi.
The keypoint variant is the paper's "low-dim" PushT input (Chi et al. 2023, Sec. 5.1: agent
position plus 2-D keypoints of the T); here the keypoints are those of
``coursekit.envs.pusht_geometry.block_keypoints`` (their number K is whatever it returns).
Features are computed identically for demonstrations (angle unwrapped) and for environment
observations (angle mod 2 pi): both are functions of sin/cos of the angle only.

A task's default features are named by its record (``coursekit.tasks``). Adding a feature set is
one :class:`FeatureSet` entry in :data:`FEATURES`; a new task whose observation is a flat vector
needs none (``raw_state``; not for PushT, whose angle is never wrapped: use ``pusht_state``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

STATE_DIM = 5
"""A PushT state: [agent_x, agent_y, block_x, block_y, block_angle]."""

STATE_FEATURE_NAMES = ("agent_x", "agent_y", "block_x", "block_y", "sin_angle", "cos_angle")
"""The label of each dimension of :func:`pusht_state_features`."""


def _check_state(state: np.ndarray, who: str) -> np.ndarray:
    state = np.asarray(state, dtype=np.float64)
    if state.ndim < 1 or state.shape[-1] < STATE_DIM:
        raise ValueError(
            f"{who}: expected PushT states of shape (..., 5) = [agent_x, agent_y, block_x, block_y, angle] "
            f"(or the 7-d get_state() with velocities), got shape {state.shape}"
        )
    if not np.all(np.isfinite(state[..., :STATE_DIM])):
        raise ValueError(f"{who}: states contain NaN or inf (first bad row: {state[~np.isfinite(state).all(-1)][:1]})")
    return state[..., :STATE_DIM]


def pusht_state_features(state: np.ndarray) -> np.ndarray:
    """[ax, ay, bx, by, angle] (..., 5) -> [ax, ay, bx, by, sin angle, cos angle] (..., 6) float32."""
    state = _check_state(state, "pusht_state_features")
    angle = state[..., 4]
    out = np.concatenate([state[..., :4], np.sin(angle)[..., None], np.cos(angle)[..., None]], axis=-1)
    return out.astype(np.float32)  # (..., 6)


def pusht_keypoint_features(state: np.ndarray) -> np.ndarray:
    """[ax, ay, bx, by, angle] (..., 5) -> [ax, ay, kp_x, kp_y for each of K keypoints] (..., 2 + 2K).

    The keypoints are the env's (``pusht_geometry.KEYPOINTS_LOCAL``), put in the world by the
    env's own body-to-world transform for all states at once.
    """
    from coursekit.envs import pusht_geometry as geo  # numpy/shapely only, no pymunk

    state = _check_state(state, "pusht_keypoint_features")
    kps = geo.local_to_world(geo.KEYPOINTS_LOCAL, state[..., None, 2:5])  # (..., K, 2)
    kps = kps.reshape(*state.shape[:-1], 2 * len(geo.KEYPOINTS_LOCAL))  # (..., 2K)
    return np.concatenate([state[..., :2], kps], axis=-1).astype(np.float32)  # (..., 2 + 2K)


def aloha_state_features(qpos: np.ndarray, env_state: np.ndarray) -> np.ndarray:
    """qpos (..., 14), env_state (..., 7 or 14) -> [qpos, env_state] (..., 21 or 28) float32."""
    return np.concatenate([np.asarray(qpos), np.asarray(env_state)], axis=-1).astype(np.float32)


def aloha_qpos_features(qpos: np.ndarray) -> np.ndarray:
    """qpos (..., 14) -> qpos (..., 14) float32 (proprioception only)."""
    return np.asarray(qpos, dtype=np.float32)


def raw_state_features(state: np.ndarray) -> np.ndarray:
    """The observation vector (..., D) as it is, float32 (refused if not finite)."""
    state = np.asarray(state, dtype=np.float64)
    if state.ndim < 1 or not np.all(np.isfinite(state)):
        raise ValueError(f"raw_state_features: expected finite observation vectors (..., D), got shape {state.shape}")
    return state.astype(np.float32)  # (..., D)


def pusht_agent_pos(state: np.ndarray) -> np.ndarray:
    """The low-dim part of 'pusht_image': [agent_x, agent_y] (..., 2) of PushT states (..., 5)."""
    return _check_state(state, "pusht_agent_pos")[..., :2].astype(np.float32)


@dataclass(frozen=True)
class FeatureSet:
    """One row of the feature table: which task, which per-step arrays, which function."""

    task: str | None
    """The world whose observations it reads: 'pusht', 'aloha' (the arm pair's tasks); None: any task."""
    reads: tuple[str, ...]
    """Per-step arrays the function takes, in order (dataset arrays or env observation keys)."""
    fn: Callable[..., np.ndarray]
    """Arrays (..., d_i) in ``reads`` order -> low-dim features (..., Do) float32."""
    obs_type: str = "low_dim"
    """'low_dim', or 'image' (a camera image beside the low-dim vector, which is then "agent_pos")."""

    def __call__(self, data: Any) -> np.ndarray:
        """Features of a mapping holding the ``reads`` arrays, or of the one array a one-array set reads."""
        if not isinstance(data, Mapping):
            if len(self.reads) != 1:
                raise ValueError(f"these features read {list(self.reads)}; pass a dict of those arrays")
            return self.fn(np.asarray(data))
        missing = [k for k in self.reads if k not in data]
        if missing:
            raise ValueError(f"features need arrays {list(self.reads)}; missing {missing} (have {sorted(data)})")
        return self.fn(*(np.asarray(data[k]) for k in self.reads))


FEATURES: dict[str, FeatureSet] = {
    "pusht_state": FeatureSet("pusht", ("state",), pusht_state_features),
    "pusht_keypoints": FeatureSet("pusht", ("state",), pusht_keypoint_features),
    "pusht_image": FeatureSet("pusht", ("state",), pusht_agent_pos, obs_type="image"),
    "aloha_state": FeatureSet("aloha", ("qpos", "env_state"), aloha_state_features),
    "aloha_qpos": FeatureSet("aloha", ("qpos",), aloha_qpos_features),
    "aloha_image": FeatureSet("aloha", ("qpos",), aloha_qpos_features, obs_type="image"),
    "raw_state": FeatureSet(None, ("state",), raw_state_features),
}
"""Feature name (stored in a policy's config) -> :class:`FeatureSet`, for every task and policy."""


def get_features(name: str) -> FeatureSet:
    """The feature set called ``name`` (a key of :data:`FEATURES`); call it on states or a dict of arrays."""
    if name not in FEATURES:
        raise ValueError(f"unknown observation features {name!r}; expected one of {sorted(FEATURES)}")
    return FEATURES[name]


def feature_dim(name: str) -> int:
    """Do, the number of low-dim features ``name`` produces per step (PushT sets and aloha_qpos)."""
    spec = get_features(name)
    if spec.task == "pusht":
        return int(spec(np.zeros(STATE_DIM)).shape[-1])
    if spec.reads == ("qpos",):
        return 14
    raise ValueError(f"the dimension of {name!r} depends on the task's objects; read it off the data")


def default_features(arrays: Mapping[str, Any], meta: Mapping[str, Any] | None = None) -> str:
    """The default features (``coursekit.tasks``) of the demonstrations' task.

    The task is the one the dataset's meta names ("task" or "env_id"); failing that, the first
    registered task whose default features read arrays the dataset has (PushT: "state"; the arm
    pair: "qpos" and "env_state").
    """
    from coursekit.tasks.registry import TASKS, task_in_meta

    task = task_in_meta(meta)
    if task is not None:
        return task.features
    for task in TASKS.values():
        if all(k in arrays for k in get_features(task.features).reads):
            return task.features
    raise ValueError(f"cannot tell the task of a dataset with arrays {sorted(arrays)} and no task in its meta; "
                     f"pass features=...")


def training_arrays(dataset: Any, features: str, image_size: tuple[int, int] = (96, 96)
                    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Demonstrations -> (observation arrays, action (N, Da) float32) for a batcher and ``fit_normalizers``.

    Low-dim features give ``{"obs": (N, Do)}``; image features give ``{"image": (N, 3, H, W) uint8,
    "agent_pos": (N, Do)}`` (PushT: the pusher, Do = 2; the arm pair: qpos, Do = 14), the images
    the data set's own "image" frames or else rendered from its stored states by the env's own
    camera (:func:`render_frames`: the data set keeps states only; 96 x 96 x 3 bytes is 28 kB a step).
    """
    spec = get_features(features)
    if "action" not in dataset.arrays:
        raise ValueError(f"dataset lacks the 'action' array (has {sorted(dataset.arrays)})")
    missing = [k for k in spec.reads if k not in dataset.arrays]
    if missing:
        raise ValueError(f"features {features!r} ({spec.task} task) need arrays {list(spec.reads)}; the dataset has "
                         f"{sorted(dataset.arrays)} (demonstrations of another task?)")
    action = np.asarray(dataset["action"], dtype=np.float32)
    if spec.obs_type != "image":
        return {"obs": spec(dataset.arrays)}, action
    if "image" in dataset.arrays:
        from coursekit.data.frames import frames_chw

        images = frames_chw(dataset["image"], tuple(image_size), "the data set's 'image' frames")  # (N, 3, H, W)
    else:
        images = render_frames(dataset, spec.task, tuple(image_size))  # (N, 3, H, W)
    return {"image": np.ascontiguousarray(images, dtype=np.uint8), "agent_pos": spec(dataset.arrays)}, action


def render_frames(dataset: Any, world: str | None, image_size: tuple[int, int]) -> np.ndarray:
    """The camera frame of every stored step, (N, 3, H, W) uint8, drawn by the env's own observation camera.

    PushT draws its "state" rows (``coursekit.envs.pusht_render``); the arm pair sets each
    "physics_qpos" row (the full MuJoCo state its demonstrations store) and renders the "top"
    camera, the one its "pixels" observations show (``coursekit.envs.aloha``).
    """
    if world == "pusht":
        from coursekit.envs.pusht_render import PushTRenderer

        renderer = PushTRenderer(image_size)
        return np.stack([renderer.render(s) for s in dataset["state"]]).transpose(0, 3, 1, 2)  # (N, 3, H, W)
    if world == "aloha":
        from coursekit.envs.aloha.env import render_physics_states
        from coursekit.tasks.registry import task_in_meta

        task = task_in_meta(dataset.meta)
        if task is None or "physics_qpos" not in dataset.arrays:
            raise ValueError(f"rendering arm-pair frames needs a data set that names its task in its meta and "
                             f"stores 'physics_qpos' (coursekit collect writes both); got meta task "
                             f"{(dataset.meta or {}).get('task')!r} and arrays {sorted(dataset.arrays)}")
        return render_physics_states(task.name, dataset["physics_qpos"], image_size)  # (N, 3, H, W)
    raise ValueError(f"no camera for the {world!r} world's frames: the data set needs an 'image' array")


def env_obs_features(name: str, observations: Sequence[Any]) -> np.ndarray:
    """B raw env observations (dicts of arrays, or PushT state vectors) -> (B, Do) low-dim features."""
    first = observations[0]
    if isinstance(first, Mapping):
        stacked = {k: np.stack([np.asarray(o[k]) for o in observations]) for k in first}  # (B, ...)
    else:
        stacked = {"state": np.stack([np.asarray(o) for o in observations])}  # (B, 5)
    return get_features(name)(stacked)
