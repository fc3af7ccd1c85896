"""Scripted demonstrations for the ALOHA tasks: waypoint experts, joint-space replay, datasets.

The recipe of ACT (Zhao et al. 2023, Sec. V and ``record_sim_episodes.py``):

1. plan timed end-effector waypoints from the spawned object poses (``transfer_cube_plan``,
   ``insertion_plan``) and run them in the END-EFFECTOR scene (mocap bodies welded to the grasp
   sites; ``coursekit.experts.aloha_waypoints``), recording the joint trajectory;
2. REPLAY that joint trajectory as actions in the joint-space environment (the one policies use);
   the replay is the demonstration;
3. keep the episode only if the replay succeeds STRICTLY (judged on its final state).

Departures from the original script, each needed for a reliable strict success (see
``shared/reference/act_aloha.md``, prototype lessons): the right gripper stays closed until step
310 and opens over 310-330 (the original opens at 220, before the left gripper has closed); grasps
aim about 1 cm above the object centre so the pitched pads clear the table; the pick orientation
is built in each arm's own frame (the right arm is yawed by pi); for insertion the grippers close
harder and the right hand is raised to the socket's opening.

Dataset arrays (per control step, episodes concatenated; see ``coursekit.data.EpisodeDataset``):
    "qpos" (N, 14), "qvel" (N, 14)   observation before the action (14-d layout)
    "action" (N, 14)                 joint targets + gripper commands sent at that step
    "env_state" (N, 7 or 14)         object poses before the action
    "physics_qpos" (N, nq), "physics_qvel" (N, nv)  full MuJoCo state before the action
                                     (``env.set_physics_state`` re-renders any camera later)
    "stage" (N,)                     published reward stage after the action
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm.auto import tqdm

from coursekit.data import EpisodeDataset
from coursekit.envs.aloha.env import AlohaEnv
from coursekit.experts.aloha_waypoints import EndEffectorScene, Waypoint, interpolate, quat_axis_angle, quat_mul

EPISODE_STEPS = 400
"""Control steps per scripted episode (8 s at 50 Hz)."""

_YAW_PI = quat_axis_angle((0, 0, 1), 180.0)  # the right arm's base orientation


def _pitch_down(base: np.ndarray, degrees: float) -> tuple[float, ...]:
    """Grasp orientation: the arm's base frame pitched about its own y axis (x tilts down)."""
    return tuple(quat_mul(base, quat_axis_angle((0, 1, 0), degrees)))


@dataclass(frozen=True)
class ScriptConfig:
    """Tunable numbers of the scripted experts (defaults: the values that pass the targets)."""

    pick_pitch_deg: float = 60.0
    """Downward pitch of the picking gripper (degrees)."""
    cube_grasp_height: float = 0.01
    """Grasp point above the cube centre (m): lower and the pitched pads hit the table."""
    meet_xyz: tuple[float, float, float] = (0.0, 0.5, 0.25)
    """Where the right gripper brings the cube for the hand-over (m)."""
    left_meet_offset: tuple[float, float, float] = (-0.008, 0.0, -0.01)
    """Left grasp site relative to meet_xyz at the hand-over (m)."""
    left_open: float = 0.7
    """Left gripper opening while it approaches the cube (normalised)."""
    release_start: int = 310
    """Step at which the right gripper starts to open (it is fully open 20 steps later)."""

    def __post_init__(self) -> None:
        if not 0.0 < self.pick_pitch_deg < 90.0:
            raise ValueError(f"pick_pitch_deg must be in (0, 90), got {self.pick_pitch_deg}")
        if not 0 < self.release_start < EPISODE_STEPS - 40:
            raise ValueError(f"release_start must be in (0, {EPISODE_STEPS - 40}), got {self.release_start}")


def transfer_cube_plan(env_state: np.ndarray, start: list[tuple[np.ndarray, np.ndarray]],
                       cfg: ScriptConfig = ScriptConfig()) -> tuple[list[Waypoint], list[Waypoint]]:
    """Waypoints (left, right) for transfer cube, from the cube pose (7,) and the start site poses."""
    cube = np.asarray(env_state[:3])
    meet = np.asarray(cfg.meet_xyz)
    (l0, lq0), (r0, rq0) = start
    pick = _pitch_down(_YAW_PI, cfg.pick_pitch_deg)
    up = np.array([0.0, 0.0, 1.0])
    # Left hand receives with its fingers vertical (closing on the cube's top and bottom faces),
    # while the right hand's pads hold the cube's +-y faces: the pads never meet.
    receive = tuple(quat_axis_angle((1, 0, 0), 90.0))
    left_meet = meet + np.asarray(cfg.left_meet_offset)
    t_rel = cfg.release_start
    right = [
        Waypoint(0, tuple(r0), tuple(rq0), 0.0),
        Waypoint(90, tuple(cube + 0.08 * up), pick, 1.0),  # above the cube
        Waypoint(130, tuple(cube + cfg.cube_grasp_height * up), pick, 1.0),  # down
        Waypoint(170, tuple(cube + cfg.cube_grasp_height * up), pick, 0.0),  # close
        Waypoint(200, tuple(meet + np.array([0.05, 0, 0])), pick, 0.0),  # lift towards the meeting point
        Waypoint(220, tuple(meet), pick, 0.0),
        Waypoint(t_rel, tuple(meet), pick, 0.0),  # hold until the left hand has closed
        Waypoint(t_rel + 20, tuple(meet), pick, 1.0),  # release
        Waypoint(t_rel + 50, tuple(meet + np.array([0.1, 0, 0.02])), pick, 1.0),  # back off to the right
        Waypoint(EPISODE_STEPS, tuple(meet + np.array([0.1, 0, 0.02])), pick, 1.0),
    ]
    left = [
        Waypoint(0, tuple(l0), tuple(lq0), 0.0),
        Waypoint(100, tuple(left_meet + np.array([-0.1, 0, 0])), receive, cfg.left_open),  # approach
        Waypoint(260, tuple(left_meet), receive, cfg.left_open),  # slide over the cube
        Waypoint(t_rel, tuple(left_meet), receive, 0.0),  # close
        Waypoint(t_rel + 50, tuple(left_meet + np.array([-0.1, 0, 0])), receive, 0.0),  # carry it away
        Waypoint(EPISODE_STEPS, tuple(left_meet + np.array([-0.1, 0, 0])), receive, 0.0),
    ]
    return left, right


def run_end_effector(task: str, env_state: np.ndarray, plan_fn, cfg: ScriptConfig = ScriptConfig(),
                     scene: EndEffectorScene | None = None) -> dict[str, np.ndarray]:
    """Execute a waypoint plan in the end-effector scene.

    Returns "qpos" (T+1, 14) joint trajectory (row 0 = start), "gripper_cmd" (T, 2) commands,
    "stage" (T,), "strict_success" () bool of the final state, "site_error" (T,) weld error (m).
    """
    scene = scene or EndEffectorScene(task)
    start = scene.reset(env_state)
    left, right = plan_fn(env_state, start, cfg)
    qpos = [scene.qpos14()]
    grip, stage, err = [], [], []
    for t in range(EPISODE_STEPS):
        lc, rc = interpolate(left, t + 1), interpolate(right, t + 1)  # aim at the next step's pose
        scene.step(lc, rc)
        qpos.append(scene.qpos14())
        grip.append((lc[2], rc[2]))
        stage.append(scene.task.stage(scene.data))
        err.append(scene.site_error())
    return {"qpos": np.array(qpos), "gripper_cmd": np.array(grip), "stage": np.array(stage),
            "strict_success": np.array(scene.task.strict_success(scene.data)), "site_error": np.array(err)}


def joint_actions(ee: dict[str, np.ndarray]) -> np.ndarray:
    """(T, 14) joint-space actions from an end-effector rollout: the joint angles reached at the
    next step as targets, and the gripper commands as they were sent."""
    actions = ee["qpos"][1:].copy()  # (T, 14)
    actions[:, [6, 13]] = ee["gripper_cmd"]
    return actions


def replay(env: AlohaEnv, env_state: np.ndarray, actions: np.ndarray) -> dict[str, np.ndarray]:
    """Replay (T, 14) actions in the joint-space env from ``env_state``; record one episode."""
    obs, _ = env.reset(options={"env_state": env_state})
    rec: dict[str, list] = {k: [] for k in ("qpos", "qvel", "env_state", "physics_qpos", "physics_qvel", "action", "stage")}
    info = {}
    for action in actions:
        phys = env.get_physics_state()
        rec["qpos"].append(obs["qpos"])
        rec["qvel"].append(obs["qvel"])
        rec["env_state"].append(obs["env_state"])
        rec["physics_qpos"].append(phys["physics_qpos"])
        rec["physics_qvel"].append(phys["physics_qvel"])
        rec["action"].append(action)
        obs, reward, terminated, truncated, info = env.step(action)
        rec["stage"].append(int(reward))
        if terminated:
            break
    episode = {k: np.asarray(v) for k, v in rec.items()}
    episode["strict_success"] = np.array(bool(info.get("strict_success", False)) and not info.get("sim_unstable", False))
    episode["lenient_success"] = np.array(int(info.get("max_stage", 0)) == 4)
    return episode
