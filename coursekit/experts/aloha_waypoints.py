"""End-effector waypoints and the mocap scene that executes them (the scripted experts' tools).

ACT's scripted experts (Zhao et al. 2023, ``scripted_policy.py``) describe each gripper as a list
of timed waypoints (position, orientation, gripper opening), interpolate between them, and move a
mocap body along the result; a weld constraint drags the arm's grasp site after it, and the arm's
joints follow. Here the weld joins two sites (mocap site <-> grasp site between the pads), so a
waypoint is directly where the pads' centre should be, with no relative-pose bookkeeping.

Orientation convention: unit quaternions [w, x, y, z] in the world frame (MuJoCo's order).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from coursekit.envs.aloha.model import (
    N_SUBSTEPS,
    START_ARM_QPOS,
    START_FINGER,
    ArmPairIndex,
    gripper_normalize,
    load_model,
)
from coursekit.envs.aloha.tasks import TASKS


# ---- quaternions ---------------------------------------------------------------------------
def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of [w, x, y, z] quaternions (rotate by b, then by a)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])


def quat_axis_angle(axis: tuple[float, float, float], degrees: float) -> np.ndarray:
    """[w, x, y, z] rotation by ``degrees`` about the unit ``axis``."""
    half = np.deg2rad(degrees) / 2
    return np.concatenate([[np.cos(half)], np.sin(half) * np.asarray(axis, dtype=float)])


def quat_slerp(q0: np.ndarray, q1: np.ndarray, frac: float) -> np.ndarray:
    """Spherical interpolation from q0 (frac 0) to q1 (frac 1) along the shorter arc."""
    dot = float(np.dot(q0, q1))
    if dot < 0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly equal: linear interpolation is exact enough and stable
        q = q0 + frac * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(dot)
    return (np.sin((1 - frac) * theta) * q0 + np.sin(frac * theta) * q1) / np.sin(theta)


# ---- waypoints -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Waypoint:
    """Where one gripper should be at control step ``t``."""

    t: int
    """Control step (50 Hz) at which the pose is reached."""
    xyz: tuple[float, float, float]
    """Grasp-site (pad centre) position in the world frame (m)."""
    quat: tuple[float, float, float, float]
    """Grasp-site orientation [w, x, y, z] in the world frame."""
    gripper: float
    """Normalised gripper command g (1 open, 0 closed; below 0 squeezes harder)."""


def interpolate(waypoints: list[Waypoint], t: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Pose (xyz (3,), quat (4,)) and gripper command at step ``t``, linear between waypoints."""
    if not waypoints or any(b.t <= a.t for a, b in zip(waypoints, waypoints[1:])):
        raise ValueError(f"waypoints must be non-empty with increasing t, got {[w.t for w in waypoints]}")
    if t <= waypoints[0].t:
        w = waypoints[0]
        return np.array(w.xyz), np.array(w.quat), w.gripper
    for a, b in zip(waypoints, waypoints[1:]):
        if t <= b.t:
            frac = (t - a.t) / (b.t - a.t)
            xyz = np.array(a.xyz) + frac * (np.array(b.xyz) - np.array(a.xyz))
            quat = quat_slerp(np.array(a.quat), np.array(b.quat), frac)
            return xyz, quat, a.gripper + frac * (b.gripper - a.gripper)
    w = waypoints[-1]
    return np.array(w.xyz), np.array(w.quat), w.gripper


# ---- the end-effector scene ----------------------------------------------------------------
class EndEffectorScene:
    """The arm pair whose grasp sites follow two mocap bodies (stiff site-to-site welds).

    ``reset(env_state)`` puts the arms in the start pose and the objects at ``env_state``;
    ``step(left, right)`` moves the mocap targets to the two (xyz, quat, g) commands and runs one
    control step (10 physics steps). ``qpos14()`` reads the arms in the 14-d layout.
    """

    def __init__(self, task: str) -> None:
        self.model = load_model(task, end_effector=True)
        self.data = mujoco.MjData(self.model)
        self.index = ArmPairIndex.from_model(self.model)
        self.task = TASKS[task](self.model)
        self.mocap = [self.model.body_mocapid[mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, f"{arm}/mocap")]
                      for arm in ("left", "right")]

    def reset(self, env_state: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Start pose + objects; returns the two grasp-site poses [(xyz (3,), quat (4,))] * 2."""
        mujoco.mj_resetData(self.model, self.data)
        self.index.set_arm_pose(self.data, np.concatenate([START_ARM_QPOS, START_ARM_QPOS]), START_FINGER)
        self.task.set_env_state(self.data, env_state)
        g = gripper_normalize(START_FINGER)
        self.index.set_gripper_ctrl(self.data, g, g)
        mujoco.mj_forward(self.model, self.data)
        poses = []
        for arm, site in enumerate(self.index.grasp_site):
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, self.data.site_xmat[site])
            xyz = self.data.site_xpos[site].copy()
            self.data.mocap_pos[self.mocap[arm]] = xyz
            self.data.mocap_quat[self.mocap[arm]] = quat
            poses.append((xyz, quat))
        return poses

    def step(self, left: tuple[np.ndarray, np.ndarray, float], right: tuple[np.ndarray, np.ndarray, float]) -> None:
        """One control step towards the (xyz, quat, g) commands of the left and right gripper."""
        for arm, (xyz, quat, _) in enumerate((left, right)):
            self.data.mocap_pos[self.mocap[arm]] = xyz
            self.data.mocap_quat[self.mocap[arm]] = quat
        self.index.set_gripper_ctrl(self.data, left[2], right[2])
        mujoco.mj_step(self.model, self.data, nstep=N_SUBSTEPS)

    def qpos14(self) -> np.ndarray:
        """(14,) current joint angles and normalised gripper positions."""
        return self.index.qpos14(self.data)

    def held_offsets(self, bodies: tuple[str, str]) -> tuple[np.ndarray, np.ndarray]:
        """World offsets (3,) of two bodies' origins from the (left, right) grasp sites."""
        ids = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, b) for b in bodies]
        left, right = (self.data.xpos[b] - self.data.site_xpos[s] for b, s in zip(ids, self.index.grasp_site))
        return left.copy(), right.copy()

    def site_error(self) -> float:
        """Largest distance (m) between a grasp site and its mocap target (weld tracking error)."""
        errs = [np.linalg.norm(self.data.site_xpos[site] - self.data.mocap_pos[self.mocap[arm]])
                for arm, site in enumerate(self.index.grasp_site)]
        return float(max(errs))
