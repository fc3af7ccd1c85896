"""The two ACT simulation tasks: object spawning, the published stage reward and a strict success.

Both tasks keep the published reward (Zhao et al. 2023, the ``sim_env`` code) for comparability:
a stage 0-4 computed from the contacts of the current physics state, with success = stage 4
reached at some step. That reward is lenient: a cube that brushes a finger of the left gripper in
mid-air while falling counts as stage 4. So each task also judges a STRICT success on the final
state of the episode (see ``strict_success``); the scripted demonstrations keep only episodes that
pass it.

Object poses ("env_state") are stored as MuJoCo free-joint coordinates: per object
[x, y, z, qw, qx, qy, qz] (7,), so transfer cube has (7,) and insertion (14,) [peg, socket].
"""

from __future__ import annotations

import mujoco
import numpy as np

from coursekit.envs.aloha.model import ArmPairIndex
from coursekit.tasks.aloha import INSERTION, TRANSFER_CUBE

_IDENTITY_QUAT = np.array([1.0, 0.0, 0.0, 0.0])
MAX_HEIGHT = 1.0
"""Highest an object may be put above the table top (m); the arms reach about 0.6 m up."""
QUAT_NORM_TOLERANCE = 0.01
"""How far from 1 a given quaternion's norm may be (recorded float32 poses are within 1e-6)."""


_KEY = 1 << 20  # geom-pair key: min(id) * _KEY + max(id), unique for any model with < 2**20 geoms


def _contact_keys(data: mujoco.MjData) -> set[int]:
    """Pair keys of every active contact (see ``_pair_keys``)."""
    geoms = data.contact.geom[: data.ncon]  # (ncon, 2)
    return set((geoms.min(axis=1) * _KEY + geoms.max(axis=1)).tolist())


def _pair_keys(group_a: list[int], group_b: list[int]) -> frozenset[int]:
    """Keys of every (a, b) geom pair between two groups, to intersect with ``_contact_keys``."""
    return frozenset(min(a, b) * _KEY + max(a, b) for a in group_a for b in group_b)


class AlohaTask:
    """One task: which free bodies it has, how they spawn, and how it is judged.

    Subclasses set ``name``, ``objects`` (free-joint body names, in env_state order) and
    ``spawn_ranges`` (per object: ((x_lo, x_hi), (y_lo, y_hi), z) in metres).
    """

    name: str = ""
    objects: tuple[str, ...] = ()
    spawn_ranges: tuple[tuple[tuple[float, float], tuple[float, float], float], ...] = ()

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.index = ArmPairIndex.from_model(model)
        self.table = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "table")]
        self.object_qpos_adr = []
        self.object_qvel_adr = []
        for body in self.objects:
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
            jnt = model.body_jntadr[bid]
            self.object_qpos_adr.append(model.jnt_qposadr[jnt])
            self.object_qvel_adr.append(model.jnt_dofadr[jnt])
        self.left_pads = self.index.pad_geoms[0].tolist()
        self.right_pads = self.index.pad_geoms[1].tolist()

    @property
    def env_state_dim(self) -> int:
        return 7 * len(self.objects)

    def _geom(self, name: str) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, name)

    # ---- object poses --------------------------------------------------------------------
    def spawn(self, rng: np.random.Generator) -> np.ndarray:
        """(7 * n_objects,) random object poses from the published spawn ranges (upright)."""
        poses = []
        for (x_range, y_range, z) in self.spawn_ranges:
            xyz = [rng.uniform(*x_range), rng.uniform(*y_range), z]
            poses.append(np.concatenate([xyz, _IDENTITY_QUAT]))
        return np.concatenate(poses)

    def workspace(self) -> tuple[np.ndarray, np.ndarray]:
        """(low (3,), high (3,)) xyz in metres where an object may be put: over the table, up to MAX_HEIGHT above it."""
        (tid,) = self.table
        centre, half = self.model.geom_pos[tid], self.model.geom_size[tid]  # a box geom: half sizes
        top = centre[2] + half[2]
        return (np.array([centre[0] - half[0], centre[1] - half[1], top]),
                np.array([centre[0] + half[0], centre[1] + half[1], top + MAX_HEIGHT]))

    def check_env_state(self, env_state: np.ndarray, name: str = "env_state") -> np.ndarray:
        """``env_state`` (7 * n_objects,) if every object is in the workspace with a unit quaternion, else ValueError.

        A pose far off the table (1e6 m) would make the published stage reward read nonsense from
        an empty scene; a zero quaternion cannot be normalised. Both are refused, naming the object.
        """
        low, high = self.workspace()
        for i, body in enumerate(self.objects):
            xyz, quat = env_state[7 * i: 7 * i + 3], env_state[7 * i + 3: 7 * i + 7]
            if np.any(xyz < low) or np.any(xyz > high):
                box = ", ".join(f"{a} in [{lo:.2f}, {hi:.2f}]" for a, lo, hi in zip("xyz", low, high))
                raise ValueError(f"{name}: the {body} at xyz {np.round(xyz, 4).tolist()} m is outside the workspace over "
                                 f"the table ({box} m)")
            norm = float(np.linalg.norm(quat))
            if abs(norm - 1.0) > QUAT_NORM_TOLERANCE:
                raise ValueError(f"{name}: the {body}'s orientation [qw qx qy qz] must be a unit quaternion (norm 1 +- "
                                 f"{QUAT_NORM_TOLERANCE:g}), got {quat.tolist()} (norm {norm:.4g})")
        return env_state

    def set_env_state(self, data: mujoco.MjData, env_state: np.ndarray) -> None:
        """Put the objects at (7 * n_objects,) poses, at rest."""
        for i, (qa, va) in enumerate(zip(self.object_qpos_adr, self.object_qvel_adr)):
            pose = np.asarray(env_state[7 * i: 7 * i + 7], dtype=float)
            data.qpos[qa: qa + 3] = pose[:3]
            data.qpos[qa + 3: qa + 7] = pose[3:] / np.linalg.norm(pose[3:])
            data.qvel[va: va + 6] = 0.0

    def env_state(self, data: mujoco.MjData) -> np.ndarray:
        """(7 * n_objects,) current object poses [x, y, z, qw, qx, qy, qz] per object."""
        return np.concatenate([data.qpos[qa: qa + 7] for qa in self.object_qpos_adr]).copy()

    # ---- judging -------------------------------------------------------------------------
    def stage(self, data: mujoco.MjData) -> int:
        """The published reward stage 0-4 of the current state (from its contacts)."""
        raise NotImplementedError

    def strict_success(self, data: mujoco.MjData) -> bool:
        """Whether the current state is a finished task (judge it on the episode's last state)."""
        raise NotImplementedError


class TransferCubeTask(AlohaTask):
    """Right arm picks the 4 cm cube and hands it to the left arm."""

    name = TRANSFER_CUBE.name
    objects = ("cube",)
    spawn_ranges = (((0.0, 0.2), (0.4, 0.6), 0.02),)
    min_height = 0.05
    """Strict success: the cube centre must be at least this high (m); it rests at 0.02."""

    def __init__(self, model: mujoco.MjModel) -> None:
        super().__init__(model)
        self.cube = [self._geom("cube")]
        self._cube_right = _pair_keys(self.cube, self.right_pads)
        self._cube_left = _pair_keys(self.cube, self.left_pads)
        self._cube_left_each = [_pair_keys(self.cube, [pad]) for pad in self.left_pads]
        self._cube_table = _pair_keys(self.cube, self.table)

    def stage(self, data: mujoco.MjData) -> int:
        # Published stages: 1 right gripper touches the cube, 2 lifted (right touches, table does
        # not), 3 left gripper touches, 4 left touches and neither the table nor the right does.
        keys = _contact_keys(data)
        right = not keys.isdisjoint(self._cube_right)
        left = not keys.isdisjoint(self._cube_left)
        table = not keys.isdisjoint(self._cube_table)
        stage = 0
        if right:
            stage = 1
        if right and not table:
            stage = 2
        if left:
            stage = 3
        if left and not table and not right:
            stage = 4
        return stage

    def strict_success(self, data: mujoco.MjData) -> bool:
        # Held by the left gripper only: both left pads touch the cube, no right pad and not the
        # table, and the cube is clear of the table.
        keys = _contact_keys(data)
        both_left = all(not keys.isdisjoint(pad) for pad in self._cube_left_each)
        right = not keys.isdisjoint(self._cube_right)
        table = not keys.isdisjoint(self._cube_table)
        z = data.qpos[self.object_qpos_adr[0] + 2]
        return bool(both_left and not right and not table and z > self.min_height)


class InsertionTask(AlohaTask):
    """Right arm picks the peg, left arm the socket; the peg goes into the socket to the pin."""

    name = INSERTION.name
    objects = ("peg", "socket")
    spawn_ranges = (((0.1, 0.2), (0.4, 0.6), 0.01), ((-0.2, -0.1), (0.4, 0.6), 0.022))
    peg_half_length = 0.06
    """Half length of the peg along its x axis (m)."""
    socket_inner_half = 0.018
    """Half width of the socket's square opening (m)."""
    socket_half_length = 0.06
    """Half length of the socket tube (m)."""
    pin_end_x = 0.02
    """Socket-frame x of the pin's free end (m): where an inserted peg tip stops."""
    tip_tolerance = 0.01
    """Strict success: the peg tip must be within this distance (m) of the pin's end."""

    def __init__(self, model: mujoco.MjModel) -> None:
        super().__init__(model)
        self.peg = [self._geom("peg")]
        self.socket_walls = [self._geom(f"socket_{w}") for w in ("bottom", "top", "back", "front")]
        self.pin = [self._geom("pin")]
        socket = self.socket_walls + self.pin
        self._left_socket = _pair_keys(socket, self.left_pads)
        self._right_peg = _pair_keys(self.peg, self.right_pads)
        self._peg_table = _pair_keys(self.peg, self.table)
        self._socket_table = _pair_keys(socket, self.table)
        self._peg_walls = _pair_keys(self.peg, self.socket_walls)
        self._peg_pin = _pair_keys(self.peg, self.pin)
        self.peg_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "peg")
        self.socket_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "socket")

    def stage(self, data: mujoco.MjData) -> int:
        # Published stages: 1 both grippers touch their objects, 2 both lifted, 3 peg touches the
        # socket (both off the table), 4 peg touches the pin.
        keys = _contact_keys(data)
        left = not keys.isdisjoint(self._left_socket)
        right = not keys.isdisjoint(self._right_peg)
        peg_table = not keys.isdisjoint(self._peg_table)
        socket_table = not keys.isdisjoint(self._socket_table)
        peg_socket = not keys.isdisjoint(self._peg_walls)
        pin = not keys.isdisjoint(self._peg_pin)
        stage = 0
        if left and right:
            stage = 1
        if left and right and not peg_table and not socket_table:
            stage = 2
        if peg_socket and not peg_table and not socket_table:
            stage = 3
        if pin:
            stage = 4
        return stage

    def peg_tip_in_socket(self, data: mujoco.MjData) -> np.ndarray:
        """(2, 3) both peg ends expressed in the socket's frame (x along the tube)."""
        ends_local = np.array([[-self.peg_half_length, 0, 0], [self.peg_half_length, 0, 0]])
        ends_world = data.xpos[self.peg_body] + ends_local @ data.xmat[self.peg_body].reshape(3, 3).T  # (2, 3)
        rot = data.xmat[self.socket_body].reshape(3, 3)  # (3, 3) socket -> world
        return (ends_world - data.xpos[self.socket_body]) @ rot  # (2, 3)

    def strict_success(self, data: mujoco.MjData) -> bool:
        # The peg end nearest the pin lies inside the tube's cross-section, within the tube, and
        # within tip_tolerance of the pin's free end.
        ends = self.peg_tip_in_socket(data)
        tip = ends[np.argmin(ends[:, 0])]
        inside = bool(np.all(np.abs(tip[1:]) < self.socket_inner_half))
        in_tube = -self.socket_half_length < tip[0] < self.pin_end_x + self.tip_tolerance
        return inside and bool(in_tube)


TASKS = {cls.name: cls for cls in (TransferCubeTask, InsertionTask)}
"""Task name (``coursekit.tasks``) -> the class that spawns and judges its objects."""
