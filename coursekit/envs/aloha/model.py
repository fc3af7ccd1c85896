"""The ALOHA arm pair as a MuJoCo model: loading the scenes and the 14-d joint/action layout.

Scenes are composed from the readable MJCF files in ``assets/``::

    aloha_pair.xml        table, two arms with grippers, cameras, finger servos (always)
    arm_actuators.xml     joint-position servos for the 12 arm joints   (joint-space scene)
    mocap_welds.xml       two mocap bodies welded to the grasp sites     (end-effector scene)
    transfer_cube.xml     the cube                                       (task objects)
    insertion.xml         the peg and the socket with its pin            (task objects)

The 14-d vector (observation ``qpos``/``qvel`` and the action) follows the original ACT code::

    index  0..5    left  arm: waist, shoulder, elbow, forearm_roll, wrist_angle, wrist_rotate (rad)
    index  6       left  gripper, normalised: g = (x - 0.01844) / (0.058 - 0.01844)
    index  7..12   right arm: same six joints (rad)
    index 13       right gripper, normalised

where x is the left finger's slide position in metres (the right finger mirrors it at -x).
g = 1 is fully open; g = 0 is the "closed" command; a closed gripper holding an object sits at
g > 0 because the object stops the fingers, and that gap times the finger gain is the grip.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # offscreen rendering on the CPU; must precede `import mujoco`

from dataclasses import dataclass  # noqa: E402
from importlib import resources  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from coursekit.tasks.aloha import CONTROL_HZ, INSERTION, TRANSFER_CUBE  # noqa: E402

ARMS = ("left", "right")
"""Arm prefixes, in the order of the 14-d layout."""
ARM_JOINTS = ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate")
"""The six rotary joints of one arm, in the order of the 14-d layout."""
STATE_NAMES = tuple(f"{arm}/{j}" for arm in ARMS for j in (*ARM_JOINTS, "gripper"))
"""Names of the 14 dimensions of qpos / qvel / action."""

START_ARM_QPOS = np.array([0.0, -0.96, 1.16, 0.0, -0.3, 0.0])
"""Published start pose of each arm's six joints (rad)."""
START_FINGER = 0.02239
"""Published start position of the fingers (m): nearly closed."""

GRIPPER_CLOSE = 0.01844
"""Finger position (m) that normalises to g = 0 (the ACT 'closed' command)."""
GRIPPER_OPEN = 0.058
"""Finger position (m) that normalises to g = 1 (fully open)."""
FINGER_CTRL_RANGE = (0.005, 0.058)
"""Finger command range in metres (the XML ctrlrange); it reaches below the joint limit (0.021)
so that a close command squeezes whatever is between the pads."""

CONTROL_DT = 1.0 / CONTROL_HZ
"""Seconds per control step: 0.02 at the arm pair's 50 Hz (``coursekit.tasks.aloha.CONTROL_HZ``)."""
PHYSICS_DT = 0.002
"""Seconds per physics step (the XML timestep)."""
N_SUBSTEPS = round(CONTROL_DT / PHYSICS_DT)
"""Physics steps per control step (10)."""

TASK_FILES = {TRANSFER_CUBE.name: "transfer_cube.xml", INSERTION.name: "insertion.xml"}
"""Task name -> the MJCF file with its objects."""


def gripper_normalize(x: np.ndarray | float) -> np.ndarray | float:
    """Finger position x (m) -> normalised gripper value g (ACT convention)."""
    return (x - GRIPPER_CLOSE) / (GRIPPER_OPEN - GRIPPER_CLOSE)


def gripper_unnormalize(g: np.ndarray | float) -> np.ndarray | float:
    """Normalised gripper value g -> finger position x (m)."""
    return GRIPPER_CLOSE + g * (GRIPPER_OPEN - GRIPPER_CLOSE)


def _read_assets() -> dict[str, bytes]:
    folder = resources.files("coursekit.envs.aloha") / "assets"
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.name.endswith(".xml")}


def scene_xml(task: str, end_effector: bool = False) -> str:
    """The top-level MJCF text of one scene: the arm pair + controls + the task's objects."""
    if task not in TASK_FILES:
        raise ValueError(f"unknown ALOHA task {task!r}; expected one of {sorted(TASK_FILES)}")
    control = "mocap_welds.xml" if end_effector else "arm_actuators.xml"
    kind = "ee" if end_effector else "joint"
    return (
        f'<mujoco model="aloha_{task}_{kind}">\n'
        f'  <include file="aloha_pair.xml"/>\n'
        f'  <include file="{control}"/>\n'
        f'  <include file="{TASK_FILES[task]}"/>\n'
        f"</mujoco>\n"
    )


def load_model(task: str, end_effector: bool = False) -> mujoco.MjModel:
    """Compile one scene: joint-position control (default) or mocap end-effector control."""
    return mujoco.MjModel.from_xml_string(scene_xml(task, end_effector), _read_assets())


@dataclass(frozen=True)
class ArmPairIndex:
    """Addresses of the 14-d layout (and the grippers' geoms) inside one compiled model.

    Attributes:
        qpos_adr: (14,) mujoco qpos address of each dimension (the left finger for a gripper).
        qvel_adr: (14,) mujoco qvel address of each dimension.
        arm_act: (12,) actuator ids of the arm joint servos, or empty in the end-effector scene.
        arm_dims: (12,) which of the 14 dimensions the arm servos drive.
        finger_act: (2, 2) actuator ids [arm, (left finger, right finger)].
        finger_qpos_adr: (2, 2) qpos addresses [arm, (left finger, right finger)].
        pad_geoms: (2, 2) geom ids of the finger pads [arm, (left pad, right pad)].
        grasp_site: (2,) site ids of the grasp sites (between the pads).
    """

    qpos_adr: np.ndarray
    qvel_adr: np.ndarray
    arm_act: np.ndarray
    arm_dims: np.ndarray
    finger_act: np.ndarray
    finger_qpos_adr: np.ndarray
    pad_geoms: np.ndarray
    grasp_site: np.ndarray

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> ArmPairIndex:
        def jid(name: str) -> int:
            return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)

        def aid(name: str) -> int:
            return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)

        def gid(name: str) -> int:
            return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)

        joints = [f"{arm}/{j}" for arm in ARMS for j in (*ARM_JOINTS, "left_finger")]
        ids = [jid(n) for n in joints]
        arm_dims = np.array([i for i in range(14) if i % 7 != 6])
        arm_act = np.array([aid(f"{arm}/{j}") for arm in ARMS for j in ARM_JOINTS])
        if np.any(arm_act < 0):
            arm_act = np.zeros(0, dtype=int)  # end-effector scene: the arms follow the mocap welds
        return cls(
            qpos_adr=model.jnt_qposadr[ids].copy(),
            qvel_adr=model.jnt_dofadr[ids].copy(),
            arm_act=arm_act,
            arm_dims=arm_dims,
            finger_act=np.array([[aid(f"{a}/left_finger"), aid(f"{a}/right_finger")] for a in ARMS]),
            finger_qpos_adr=np.array([[model.jnt_qposadr[jid(f"{a}/{f}")] for f in ("left_finger", "right_finger")] for a in ARMS]),
            pad_geoms=np.array([[gid(f"{a}/left_pad"), gid(f"{a}/right_pad")] for a in ARMS]),
            grasp_site=np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{a}/grasp_site") for a in ARMS]),
        )

    # ---- reading the 14-d state --------------------------------------------------------
    def qpos14(self, data: mujoco.MjData) -> np.ndarray:
        """(14,) joint angles and normalised gripper positions."""
        q = data.qpos[self.qpos_adr].copy()
        q[[6, 13]] = gripper_normalize(q[[6, 13]])
        return q

    def qvel14(self, data: mujoco.MjData) -> np.ndarray:
        """(14,) joint velocities (rad/s) and finger velocities in normalised units per second."""
        v = data.qvel[self.qvel_adr].copy()
        v[[6, 13]] /= GRIPPER_OPEN - GRIPPER_CLOSE
        return v

    # ---- writing commands and poses ----------------------------------------------------
    def set_gripper_ctrl(self, data: mujoco.MjData, g_left: float, g_right: float) -> None:
        """Drive each gripper's two fingers to +-x(g) (clipped to the finger command range)."""
        for arm, g in enumerate((g_left, g_right)):
            x = float(np.clip(gripper_unnormalize(g), *FINGER_CTRL_RANGE))
            data.ctrl[self.finger_act[arm, 0]] = x
            data.ctrl[self.finger_act[arm, 1]] = -x

    def set_action(self, data: mujoco.MjData, action: np.ndarray) -> None:
        """Write a (14,) action into the servos' ctrl (the XML ctrlrange clips the joints)."""
        data.ctrl[self.arm_act] = action[self.arm_dims]
        self.set_gripper_ctrl(data, action[6], action[13])

    def set_arm_pose(self, data: mujoco.MjData, arm_qpos12: np.ndarray, finger: float) -> None:
        """Place both arms: (12,) joint angles [left 6, right 6] and the finger opening x (m)."""
        data.qpos[self.qpos_adr[self.arm_dims]] = arm_qpos12
        data.qpos[self.finger_qpos_adr[:, 0]] = finger
        data.qpos[self.finger_qpos_adr[:, 1]] = -finger


def action_bounds(pair_model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """(14,) low and high of the action space: joint ranges and the gripper command range."""
    low, high = np.zeros(14), np.zeros(14)
    idx = ArmPairIndex.from_model(pair_model)
    low[idx.arm_dims] = pair_model.actuator_ctrlrange[idx.arm_act, 0]
    high[idx.arm_dims] = pair_model.actuator_ctrlrange[idx.arm_act, 1]
    low[[6, 13]] = gripper_normalize(FINGER_CTRL_RANGE[0])
    high[[6, 13]] = gripper_normalize(FINGER_CTRL_RANGE[1])
    return low, high


def start_qpos14() -> np.ndarray:
    """(14,) the published start pose in the 14-d layout."""
    g = gripper_normalize(START_FINGER)
    return np.concatenate([START_ARM_QPOS, [g], START_ARM_QPOS, [g]])
