"""The arm pair's two ACT tasks (Zhao et al. 2023, Sec. V): transfer cube and insertion.

Both run the same simulated ALOHA pair (``coursekit.envs.aloha``) at the same rate and episode
length. Evaluation protocol (ACT's): episodes of 400 control steps from held-out spawn seeds.
Each task has four reward stages (transfer cube: touched, lifted, received, held by the left
gripper; insertion: both grasped, both lifted, peg touches socket, inserted). Reported:

- ``stage_rates[s]`` for s = 1..4: fraction of episodes whose stage reached >= s at some step
  (the paper's table); stage 4 at any step is the published (lenient) success;
- ``strict_success_rate``: fraction of episodes whose FINAL state is a finished task (the cube
  still held, the peg still in the socket), the stricter judgement the demonstrations pass.

The env's reward is the stage, so ``EvalResult.score`` is the mean highest stage (0..4) and
``success_rate`` the published (lenient) success.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coursekit.tasks.record import ReplayDrawing, Task

CONTROL_HZ = 50.0
"""The arm pair's control rate: one action every 20 ms, as the real ALOHA."""
EPISODE_STEPS = 400
"""Control steps per episode (8 s): evaluation and the scripted demonstrations."""
STATE_COLUMNS = ("stage", "strict_success", *(f"qpos_{i}" for i in range(14)))
"""First 16 columns of the state an arm-pair evaluation records per step; the rest (nq) is the full
MuJoCo ``physics_qpos`` (for ``coursekit.viz.meshcat.mujoco_model`` animations and replays)."""


def arm_pair_state(env: Any) -> np.ndarray:
    """[stage, strict_success, qpos (14), physics_qpos (nq)] of an env's current state: (16 + nq,)."""
    e = env.unwrapped
    return np.concatenate([[float(e.stage()), float(e.strict_success())], e.index.qpos14(e.data), e.data.qpos])


def arm_pair_metrics(result: Any) -> dict[str, Any]:
    """ACT's per-stage success rates and the strict final-state success, from the recorded states."""
    stage = result.states[:, :, 0].max(axis=1)  # (N,) highest stage reached at any step
    strict = result.states[:, -1, 1] > 0.5  # (N,) judged on the final state
    return {"stage_rates": {s: float(np.mean(stage >= s)) for s in range(1, 5)},
            "strict_success_rate": float(np.mean(strict))}


def arm_pair_scores(result: Any) -> tuple[np.ndarray, np.ndarray]:
    """Score: the highest stage reached (0..4, the reward); success: the strict (final-state) judgement."""
    return result.states[:, :, 0].max(axis=1), result.states[:, -1, 1] > 0.5


def _top_camera(image_hw: tuple[int, int]) -> dict[str, Any]:
    """Env kwargs of an image policy: "pixels" (H, W, 3) from the "top" camera beside "qpos" (14,)."""
    return {"obs_type": "pixels", "render_size": tuple(image_hw)}


def _arm_pair_task(name: str, alias: str, gym_id: str, env: str, expert: str) -> Task:
    return Task(name=name, gym_id=gym_id, env=env, control_hz=CONTROL_HZ, max_steps=EPISODE_STEPS,
                features="aloha_state", aliases=(alias,), expert=expert, expert_options=("workers",), demo_episodes=50,
                state_fn=arm_pair_state, metrics_fn=arm_pair_metrics, scores_fn=arm_pair_scores, image_env_kwargs=_top_camera,
                replay=ReplayDrawing(viewer="mujoco", columns=(len(STATE_COLUMNS), None), panel_hw=(240, 320),
                                     camera="angle"))


TRANSFER_CUBE = _arm_pair_task("transfer_cube", "aloha-cube", "coursekit/AlohaTransferCube-v0",
                               "coursekit.envs.aloha:AlohaTransferCubeEnv",
                               "coursekit.experts.aloha_scripted:collect_transfer_cube")
"""Transfer cube: the right arm picks the 4 cm cube and hands it to the left arm."""
INSERTION = _arm_pair_task("insertion", "aloha-insertion", "coursekit/AlohaInsertion-v0",
                           "coursekit.envs.aloha:AlohaInsertionEnv", "coursekit.experts.aloha_scripted:collect_insertion")
"""Insertion: the right arm's peg goes into the socket the left arm holds, down to the pin."""
