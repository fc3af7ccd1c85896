"""Closed-loop evaluation on the ALOHA arm pair, with ACT's per-stage success rates.

Protocol (Zhao et al. 2023, Sec. V; ``shared/reference/act_aloha.md``): episodes of 400 control
steps from held-out spawn seeds (100000 + i; demonstrations use small seeds). Each task has four
reward stages (transfer cube: touched, lifted, received, held by the left gripper; insertion:
both grasped, both lifted, peg touches socket, inserted). Reported:

- ``stage_rates[s]`` for s = 1..4: fraction of episodes whose stage reached >= s at some step
  (the paper's table); stage 4 at any step is the published (lenient) success;
- ``strict_success_rate``: fraction of episodes whose FINAL state is a finished task (the cube
  still held, the peg still in the socket) — the stricter judgement the demonstrations pass.

It reuses :func:`coursekit.evaluate.rollout` (B environments in lock-step, any executor).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from coursekit.evaluate import EvalResult, check_seeds_disjoint, heldout_seeds, rollout

ALOHA_TASKS = {"transfer_cube": "AlohaTransferCubeEnv", "insertion": "AlohaInsertionEnv"}
"""Task name -> environment class in :mod:`coursekit.envs.aloha`."""

STATE_COLUMNS = ("stage", "strict_success", *(f"qpos_{i}" for i in range(14)))
"""First 16 columns of ``EvalResult.states`` recorded by :func:`evaluate_aloha`; the rest (nq) is
the full MuJoCo ``physics_qpos`` (for ``coursekit.viz.mujoco_meshcat`` animations)."""


def _record_state(env: Any) -> np.ndarray:
    """[stage, strict_success, qpos (14), physics_qpos (nq)] of an env's current state."""
    e = env.unwrapped
    return np.concatenate([[float(e.stage()), float(e.strict_success())], e.index.qpos14(e.data),
                           e.data.qpos])  # (16 + nq,)


def evaluate_aloha(policy: Any, task: str = "transfer_cube", n_episodes: int = 50, seeds: Sequence[int] | None = None,
                   max_steps: int = 400, executor_cls: Any = None,
                   executor_factory: Callable[[Callable[[Any], Any]], Any] | None = None,
                   dataset_meta: dict[str, Any] | None = None, progress: bool = True) -> EvalResult:
    """Evaluate a state-based chunk policy (``config.features`` names its ACT features) on an ALOHA task.

    Args:
        policy: a ChunkPolicy whose ``config.features`` is a key of ``ACT_FEATURES`` (e.g. ACT).
        task: 'transfer_cube' or 'insertion'.
        n_episodes, seeds: episodes to run (default seeds :func:`heldout_seeds`).
        max_steps: control steps per episode (400 = 8 s).
        executor_cls / executor_factory: replace the policy's default executor (``policy.make_executor``).
        dataset_meta: demonstrations' meta; overlapping seeds are refused.

    Returns an :class:`EvalResult` whose ``info`` has "stage_rates" {1..4: rate},
    "strict_success_rate" and the executor used; ``states`` (N, T+1, 16 + nq) holds
    [stage, strict_success, qpos (14), physics_qpos (nq)] per step (see :data:`STATE_COLUMNS`).
    """
    import coursekit.envs.aloha as aloha
    from coursekit.data.act_batches import env_obs_features

    if task not in ALOHA_TASKS:
        raise ValueError(f"task must be one of {sorted(ALOHA_TASKS)}, got {task!r}")
    env_cls = getattr(aloha, ALOHA_TASKS[task])
    seeds = list(seeds) if seeds is not None else heldout_seeds(n_episodes)
    check_seeds_disjoint(seeds, dataset_meta)
    features = policy.config.features
    policy.eval()
    policy.reset()
    factory = executor_factory or (lambda pc: policy.make_executor(pc, executor_cls=executor_cls))
    result = rollout(policy.predict_chunk, lambda: env_cls(max_episode_steps=max_steps),
                     lambda obs: env_obs_features(features, obs), seeds, factory, max_steps=max_steps,
                     progress=progress, record=True, state_fn=_record_state,
                     desc=f"eval {getattr(policy, 'policy_type', '')} {task}")
    stage = result.states[:, :, 0].max(axis=1)  # (N,) highest stage reached at any step
    strict = result.states[:, -1, 1] > 0.5  # (N,) judged on the final state
    c = policy.config
    result.info.update({
        "policy_type": getattr(policy, "policy_type", ""), "task": task, "max_steps": max_steps,
        "stage_rates": {s: float(np.mean(stage >= s)) for s in range(1, 5)},
        "strict_success_rate": float(np.mean(strict)),
        "executor": type(factory(policy.predict_chunk)).__name__,
        "temporal_ensembling": bool(getattr(c, "temporal_ensembling", False)),
        "ensemble_decay": getattr(c, "ensemble_decay", None),
    })
    return result
