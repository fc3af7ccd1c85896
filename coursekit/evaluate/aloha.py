"""Closed-loop evaluation on the ALOHA arm pair, with ACT's per-stage success rates.

Protocol (Zhao et al. 2023, Sec. V): episodes of 400 control
steps from held-out spawn seeds (100000 + i; demonstrations use small seeds). Each task has four
reward stages (transfer cube: touched, lifted, received, held by the left gripper; insertion:
both grasped, both lifted, peg touches socket, inserted). Reported:

- ``stage_rates[s]`` for s = 1..4: fraction of episodes whose stage reached >= s at some step
  (the paper's table); stage 4 at any step is the published (lenient) success;
- ``strict_success_rate``: fraction of episodes whose FINAL state is a finished task (the cube
  still held, the peg still in the socket) — the stricter judgement the demonstrations pass.

The env's reward is the stage, so ``EvalResult.score`` is the mean highest stage (0..4) and
``success_rate`` the published (lenient) success.

The adapter plugs the arm pair into :func:`coursekit.evaluate.closed_loop.evaluate` (B environments in
lock-step, any policy, any executor).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from coursekit.evaluate.result import EvalResult, heldout_seeds
from coursekit.evaluate.closed_loop import evaluate

ALOHA_TASKS = {"transfer_cube": "AlohaTransferCubeEnv", "insertion": "AlohaInsertionEnv"}
"""Task name -> environment class in :mod:`coursekit.envs.aloha`."""

STATE_COLUMNS = ("stage", "strict_success", *(f"qpos_{i}" for i in range(14)))
"""First 16 columns of ``EvalResult.states`` recorded on the arm pair; the rest (nq) is the full
MuJoCo ``physics_qpos`` (for ``coursekit.viz.meshcat.mujoco_model`` animations and replays)."""


class ArmPairAdapter:
    """One arm-pair task for :func:`coursekit.evaluate.closed_loop.evaluate`; features from the policy's config."""

    max_steps = 400
    record_always = True  # the stage rates are read off the recorded states

    def __init__(self, policy: Any, task: str = "transfer_cube") -> None:
        from coursekit.data.features import get_features

        if task not in ALOHA_TASKS:
            raise ValueError(f"task must be one of {sorted(ALOHA_TASKS)}, got {task!r}")
        self.task = task
        self.features = policy.config.features
        if get_features(self.features).task != "aloha":
            raise ValueError(f"policy features {self.features!r} are not arm-pair features; evaluate it on its own task")

    def make_env(self, max_steps: int) -> Any:
        import coursekit.envs.aloha as aloha

        return getattr(aloha, ALOHA_TASKS[self.task])(max_episode_steps=max_steps)

    def obs_fn(self, observations: list[Any]) -> np.ndarray:
        from coursekit.data.features import env_obs_features

        return env_obs_features(self.features, observations)  # (B, Do)

    def state_fn(self, env: Any) -> np.ndarray:
        """[stage, strict_success, qpos (14), physics_qpos (nq)] of an env's current state."""
        e = env.unwrapped
        return np.concatenate([[float(e.stage()), float(e.strict_success())], e.index.qpos14(e.data),
                               e.data.qpos])  # (16 + nq,)

    def metrics(self, result: EvalResult) -> dict[str, Any]:
        stage = result.states[:, :, 0].max(axis=1)  # (N,) highest stage reached at any step
        strict = result.states[:, -1, 1] > 0.5  # (N,) judged on the final state
        return {"stage_rates": {s: float(np.mean(stage >= s)) for s in range(1, 5)},
                "strict_success_rate": float(np.mean(strict))}

    def replay_states(self, result: EvalResult) -> np.ndarray:
        return result.states[..., len(STATE_COLUMNS):]  # (N, T+1, nq) MuJoCo qpos

    def episode_scores(self, result: EvalResult) -> tuple[np.ndarray, np.ndarray]:
        """Score: the highest stage reached (0..4, the reward); success: the strict (final-state) judgement."""
        return result.states[:, :, 0].max(axis=1), result.states[:, -1, 1] > 0.5


def evaluate_aloha(policy: Any, task: str = "transfer_cube", n_episodes: int = 50, seeds: Sequence[int] | None = None,
                   max_steps: int = 400, executor_cls: Any = None,
                   executor_factory: Callable[[Callable[[Any], Any]], Any] | None = None,
                   dataset_meta: dict[str, Any] | None = None, progress: bool = True, seed: int = 0) -> EvalResult:
    """Evaluate a state-based chunk policy (any type, on arm-pair features) on an ALOHA task.

    Args:
        policy: a ChunkPolicy whose ``config.features`` are arm-pair features (e.g. 'aloha_state').
        task: 'transfer_cube' or 'insertion'.
        n_episodes, seeds: episodes to run (default seeds :func:`heldout_seeds`).
        max_steps: control steps per episode (400 = 8 s).
        executor_cls / executor_factory: replace the policy's default executor (``policy.make_executor``).
        dataset_meta: demonstrations' meta; overlapping seeds are refused.
        seed: seeds the sampling noise of policies that sample (Diffusion Policy).

    Returns an :class:`EvalResult` whose ``info`` has "stage_rates" {1..4: rate},
    "strict_success_rate" and the executor used; ``states`` (N, T+1, 16 + nq) holds
    [stage, strict_success, qpos (14), physics_qpos (nq)] per step (see :data:`STATE_COLUMNS`).
    """
    return evaluate(policy, ArmPairAdapter(policy, task), list(seeds) if seeds is not None else heldout_seeds(n_episodes),
                    max_steps=max_steps, seed=seed, executor_cls=executor_cls, executor_factory=executor_factory,
                    dataset_meta=dataset_meta, progress=progress)
