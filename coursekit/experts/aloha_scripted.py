"""Scripted demonstrations for the ALOHA tasks: waypoint experts, joint-space replay, datasets.

The recipe of ACT (Zhao et al. 2023, Sec. V and ``record_sim_episodes.py``):

1. plan timed end-effector waypoints from the spawned object poses (``transfer_cube_plan``,
   ``insertion_plan``) and run them in the END-EFFECTOR scene (mocap bodies welded to the grasp
   sites; ``coursekit.experts.aloha_waypoints``), recording the joint trajectory;
2. REPLAY that joint trajectory as actions in the joint-space environment (the one policies use);
   the replay is the demonstration;
3. keep the episode only if the replay succeeds STRICTLY (judged on its final state).

Departures from the original script, each made for a reliable strict success (the strict success
they give is measured by ``benchmarks/bench_aloha.py``): the right gripper stays closed until step
310 and opens over 310-330 (the original opens at 220, before the left gripper has closed); grasps
aim about 1 cm above the object centre so the pitched pads clear the table; the pick orientation
is built in each arm's own frame (the right arm is yawed by pi); for insertion the grippers close
harder (command 0.010 m) and, once both objects are lifted, the meeting poses are re-aimed at
where the peg and socket really sit in the grippers (ACT hard-codes such an offset instead).

Dataset arrays (per control step, episodes concatenated; see ``coursekit.data.EpisodeDataset``):
    "qpos" (N, 14), "qvel" (N, 14)   observation before the action (14-d layout)
    "action" (N, 14)                 joint targets + gripper commands sent at that step
    "env_state" (N, 7 or 14)         object poses before the action
    "physics_qpos" (N, nq), "physics_qvel" (N, nv)  full MuJoCo state before the action
                                     (``env.set_physics_state`` re-renders any camera later)
    "stage" (N,)                     published reward stage after the action
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass

import numpy as np
from tqdm.auto import tqdm

from coursekit.data import EpisodeDataset
from coursekit.envs.aloha.env import AlohaEnv
from coursekit.envs.aloha.model import STATE_NAMES
from coursekit.experts.aloha_waypoints import EndEffectorScene, Waypoint, interpolate, quat_axis_angle, quat_mul
from coursekit.tasks.aloha import EPISODE_STEPS, INSERTION, TRANSFER_CUBE
from coursekit.tasks.registry import get_task

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
    insert_pitch_deg: float = 60.0
    """Downward pitch of both grippers in the insertion task (degrees)."""
    peg_grasp_height: float = 0.008
    """Insertion: grasp point above the peg centre (m)."""
    socket_grasp_height: float = 0.008
    """Insertion: grasp point above the socket centre (m)."""
    insert_close: float = -0.213
    """Insertion: gripper close command (normalised; -0.213 = fingers driven to 0.010 m)."""
    insert_meet_xyz: tuple[float, float, float] = (0.0, 0.5, 0.15)
    """Insertion: the socket's grasp site goes to meet_x - 0.045 at this height (m)."""
    insert_push: float = 0.005
    """Insertion: how far the plan drives the peg tip past the pin's end (m)."""
    measure_grasp: bool = True
    """Insertion: re-aim the meeting poses at how the objects really sit in the grippers (after
    the lift); False = ACT-style open loop, trusting the planned grasp offsets."""

    def __post_init__(self) -> None:
        if not 0.0 < self.pick_pitch_deg < 90.0:
            raise ValueError(f"pick_pitch_deg must be in (0, 90), got {self.pick_pitch_deg}")
        if not 260 < self.release_start < EPISODE_STEPS - 50:
            raise ValueError(f"release_start must be in (260, {EPISODE_STEPS - 50}) (after the left hand arrives), "
                             f"got {self.release_start}")


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


def insertion_plan(env_state: np.ndarray, start: list[tuple[np.ndarray, np.ndarray]],
                   cfg: ScriptConfig = ScriptConfig(),
                   held: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[list[Waypoint], list[Waypoint]]:
    """Waypoints (left, right) for insertion, from the peg + socket poses (14,) and the start poses.

    Both hands pick from above (pads on the objects' +-y faces) and lift; then the peg's axis is
    put on the socket's axis and the right hand pushes the peg in until its tip meets the pin
    (socket-frame x = +0.02, i.e. 4 cm deep). ``held`` = (socket centre - left grasp site, peg
    centre - right grasp site) in world coordinates, measured once both objects are lifted
    (step ``INSERTION_REPLAN_STEP``): the meeting targets correct for where each object really
    sits in its gripper. This feedback is a deliberate departure from ACT's open-loop script,
    whose fixed offsets ("lift_right = 0.00715") are tuned to one model.
    """
    peg, socket = np.asarray(env_state[:3]), np.asarray(env_state[7:10])
    (l0, lq0), (r0, rq0) = start
    up = np.array([0.0, 0.0, 1.0])
    pick_r = _pitch_down(_YAW_PI, cfg.insert_pitch_deg)
    pick_l = _pitch_down(np.array([1.0, 0, 0, 0]), cfg.insert_pitch_deg)
    g_close = cfg.insert_close
    peg_grip = peg + cfg.peg_grasp_height * up
    socket_grip = socket + cfg.socket_grasp_height * up
    off_socket, off_peg = held if held is not None else (-cfg.socket_grasp_height * up, -cfg.peg_grasp_height * up)
    meet = np.asarray(cfg.insert_meet_xyz)
    # The socket's centre goes to meet - 4.5 cm in x; the peg's centre onto the socket's axis,
    # 6 cm (half a peg) beyond the pin's end (socket-frame x = +0.02), pushed in by insert_push.
    socket_target = meet + np.array([-0.045, 0, 0])
    peg_target = socket_target + np.array([0.02 + 0.06 - cfg.insert_push, 0, 0])
    left_final = socket_target - off_socket
    right_final = peg_target - off_peg
    right_ready = right_final + np.array([0.06, 0, 0])  # peg tip 1 cm before the socket's mouth
    t_lift = INSERTION_REPLAN_STEP
    left = [
        Waypoint(0, tuple(l0), tuple(lq0), 0.0),
        Waypoint(120, tuple(socket_grip + 0.08 * up), pick_l, 1.0),  # above the socket
        Waypoint(170, tuple(socket_grip), pick_l, 1.0),  # down
        Waypoint(220, tuple(socket_grip), pick_l, g_close),  # close (firmly)
        Waypoint(t_lift, tuple(socket_grip + 0.06 * up), pick_l, g_close),  # lift
        Waypoint(285, tuple(left_final), pick_l, g_close),  # to the meeting point
        Waypoint(EPISODE_STEPS, tuple(left_final), pick_l, g_close),
    ]
    right = [
        Waypoint(0, tuple(r0), tuple(rq0), 0.0),
        Waypoint(120, tuple(peg_grip + 0.08 * up), pick_r, 1.0),
        Waypoint(170, tuple(peg_grip), pick_r, 1.0),
        Waypoint(220, tuple(peg_grip), pick_r, g_close),
        Waypoint(t_lift, tuple(peg_grip + 0.06 * up), pick_r, g_close),
        Waypoint(285, tuple(right_ready), pick_r, g_close),  # line up with the socket
        Waypoint(340, tuple(right_final), pick_r, g_close),  # insert
        Waypoint(EPISODE_STEPS, tuple(right_final), pick_r, g_close),
    ]
    return left, right


INSERTION_REPLAN_STEP = 250
"""Step at which the insertion expert measures how the objects sit in the grippers."""


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
        if task == INSERTION.name and t == INSERTION_REPLAN_STEP and cfg.measure_grasp:
            left, right = plan_fn(env_state, start, cfg, held=scene.held_offsets(("socket", "peg")))
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


# ---- demonstrations ------------------------------------------------------------------------
PLANS = {TRANSFER_CUBE.name: transfer_cube_plan, INSERTION.name: insertion_plan}
"""Task name -> waypoint planner."""


def scripted_episode(task: str, seed: int, cfg: ScriptConfig = ScriptConfig(), env: AlohaEnv | None = None,
                     scene: EndEffectorScene | None = None) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """One scripted demonstration: spawn by ``seed``, plan, run in the mocap scene, replay.

    Returns (replayed episode, end-effector rollout); see ``replay`` and ``run_end_effector``.
    """
    if task not in PLANS:
        raise ValueError(f"unknown ALOHA task {task!r}; expected one of {sorted(PLANS)}")
    env = env or AlohaEnv(task)
    env.reset(seed=seed)
    env_state = env.task.env_state(env.data)
    ee = run_end_effector(task, env_state, PLANS[task], cfg, scene=scene)
    return replay(env, env_state, joint_actions(ee)), ee


def _run_seeds(task: str, seeds: list[int], cfg: ScriptConfig) -> list[tuple[int, dict[str, np.ndarray]]]:
    """Scripted episodes for ``seeds`` with one env and scene (a worker's unit of work)."""
    env, scene = AlohaEnv(task), EndEffectorScene(task)
    out = [(s, scripted_episode(task, s, cfg, env, scene)[0]) for s in seeds]
    env.close()
    return out


def worker_context() -> multiprocessing.context.BaseContext:
    """The start method of collect()'s worker processes: forkserver, or spawn where there is none.

    Never fork: the caller may be a Jupyter kernel, whose ZMQ and IOPub threads hold locks that a
    fork copies in whatever state they are in (POSIX: only async-signal-safe calls are allowed in
    the child of a multi-threaded process; CPython 3.12 warns, 3.14 makes forkserver the default).
    Like spawn, forkserver imports the caller's main module in each worker, so a script that calls
    collect() with more than one worker needs an ``if __name__ == "__main__":`` guard.
    """
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def _map_workers(pool: ProcessPoolExecutor | None, args: tuple[list, ...]):
    """``_run_seeds`` over ``args`` in the pool (or here); a worker dead at start gets one clear line."""
    if pool is None:
        yield from map(_run_seeds, *args)
        return
    try:
        yield from pool.map(_run_seeds, *args)
    except BrokenProcessPool as exc:
        raise RuntimeError("a worker process of collect() died (run from a script? its top level must be "
                           "guarded by `if __name__ == \"__main__\":`; or pass workers=1)") from exc


def collect(task: str, n_episodes: int, seed: int = 0, progress: bool = True, cfg: ScriptConfig = ScriptConfig(),
            max_attempts: int | None = None, workers: int | None = None) -> EpisodeDataset:
    """``n_episodes`` strictly successful scripted demonstrations of ``task`` as a dataset.

    Attempt ``i`` uses spawn seed ``seed + i``; failed replays are skipped (their seeds are listed
    in ``meta["failed_seeds"]``): the dataset holds the first ``n_episodes`` successful seeds, so it
    is the same for any number of ``workers`` (processes; default: up to 2, one per core).
    Raises RuntimeError after ``max_attempts`` (default 2 * n_episodes + 10) attempts.
    """
    if n_episodes < 1:
        raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
    max_attempts = max_attempts or 2 * n_episodes + 10
    workers = workers or min(2, os.cpu_count() or 1)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    kept, kept_seeds, failed_seeds, lenient = [], [], [], 0
    bar = tqdm(total=n_episodes, desc=f"aloha {task} demos", disable=not progress, unit="ep")
    next_seed, last_seed = seed, seed + max_attempts
    pool = ProcessPoolExecutor(workers, mp_context=worker_context()) if workers > 1 else None
    try:
        while len(kept) < n_episodes:
            # Exactly as many attempts as demonstrations are missing: the kept seeds are then the
            # first n successful ones, whatever the batching.
            batch = list(range(next_seed, min(next_seed + n_episodes - len(kept), last_seed)))
            if not batch:
                raise RuntimeError(f"only {len(kept)} of {n_episodes} {task} demonstrations succeeded "
                                   f"in {max_attempts} attempts (failed seeds {failed_seeds[:20]})")
            next_seed += len(batch)
            size = max(1, -(-len(batch) // (4 * workers)))  # ceil: about 4 chunks per worker, for the progress bar
            chunks = [batch[i: i + size] for i in range(0, len(batch), size)]
            args = ([task] * len(chunks), chunks, [cfg] * len(chunks))
            for results in _map_workers(pool, args):
                for s, episode in results:
                    lenient += int(episode.pop("lenient_success"))
                    if bool(episode.pop("strict_success")):
                        kept.append(episode)
                        kept_seeds.append(s)
                        bar.update(1)
                    else:
                        failed_seeds.append(s)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
        bar.close()
    attempts = next_seed - seed
    meta = {
        "env_id": get_task(task).gym_id, "task": task, "obs_type": "state", "expert": "aloha_scripted (mocap waypoints, joint replay)",
        "seed": seed, "n_episodes": n_episodes, "attempts": attempts, "episode_seeds": kept_seeds,
        "failed_seeds": failed_seeds, "strict_successes": len(kept), "lenient_successes": lenient,
        "state_names": list(STATE_NAMES), "control_hz": get_task(task).control_hz, "script_config": asdict(cfg),
    }
    return EpisodeDataset.from_episodes(kept, meta)


def collect_transfer_cube(n_episodes: int, seed: int = 0, progress: bool = True,
                          workers: int | None = None) -> EpisodeDataset:
    """Scripted transfer-cube demonstrations (``coursekit collect aloha-cube``); ``workers`` as in :func:`collect`."""
    return collect(TRANSFER_CUBE.name, n_episodes, seed, progress, workers=workers)


def collect_insertion(n_episodes: int, seed: int = 0, progress: bool = True,
                      workers: int | None = None) -> EpisodeDataset:
    """Scripted insertion demonstrations (``coursekit collect aloha-insertion``); ``workers`` as in :func:`collect`."""
    return collect(INSERTION.name, n_episodes, seed, progress, workers=workers)
