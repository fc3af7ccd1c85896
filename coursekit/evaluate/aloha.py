"""``evaluate_aloha``: a policy on an arm-pair task by ACT's protocol (``coursekit.tasks.aloha``).

Protocol (Zhao et al. 2023, Sec. V): episodes of ``EPISODE_STEPS`` (400) control
steps from held-out spawn seeds (100000 + i; demonstrations use small seeds). Each task has four
reward stages (transfer cube: touched, lifted, received, held by the left gripper; insertion:
both grasped, both lifted, peg touches socket, inserted). Reported:

- ``stage_rates[s]`` for s = 1..4: fraction of episodes whose stage reached >= s at some step
  (the paper's table); stage 4 at any step is the published (lenient) success;
- ``strict_success_rate``: fraction of episodes whose FINAL state is a finished task (the cube
  still held, the peg still in the socket) — the stricter judgement the demonstrations pass.

The env's reward is the stage, so ``EvalResult.score`` is the mean highest stage (0..4) and
``success_rate`` the published (lenient) success.

The task's record (``coursekit.tasks.aloha``) plugs the arm pair into
:func:`coursekit.evaluate.closed_loop.evaluate` (B environments in lock-step, any policy, any executor).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from coursekit.evaluate.closed_loop import evaluate
from coursekit.evaluate.result import EvalResult, heldout_seeds
from coursekit.evaluate.tasks import make_adapter
from coursekit.tasks.aloha import TRANSFER_CUBE


def evaluate_aloha(policy: Any, task: str = TRANSFER_CUBE.name, n_episodes: int = 50, seeds: Sequence[int] | None = None,
                   max_steps: int | None = None, executor_cls: Any = None,
                   executor_factory: Callable[[Callable[[Any], Any]], Any] | None = None,
                   dataset_meta: dict[str, Any] | None = None, progress: bool = True, seed: int = 0) -> EvalResult:
    """Evaluate a state-based chunk policy (any type, on arm-pair features) on an ALOHA task.

    Args:
        policy: a ChunkPolicy whose ``config.features`` are arm-pair features (e.g. 'aloha_state').
        task: 'transfer_cube' or 'insertion'.
        n_episodes, seeds: episodes to run (default seeds :func:`heldout_seeds`).
        max_steps: control steps per episode (default: the protocol's ``EPISODE_STEPS``, 8 s).
        executor_cls / executor_factory: replace the policy's default executor (``policy.make_executor``).
        dataset_meta: demonstrations' meta; overlapping seeds are refused.
        seed: seeds the sampling noise of policies that sample (Diffusion Policy).

    Returns an :class:`EvalResult` whose ``info`` has "stage_rates" {1..4: rate},
    "strict_success_rate" and the executor used; ``states`` (N, T+1, 16 + nq) holds
    [stage, strict_success, qpos (14), physics_qpos (nq)] per step (``coursekit.tasks.aloha.STATE_COLUMNS``).
    """
    return evaluate(policy, make_adapter(task, policy), list(seeds) if seeds is not None else heldout_seeds(n_episodes),
                    max_steps=max_steps, seed=seed, executor_cls=executor_cls, executor_factory=executor_factory,
                    dataset_meta=dataset_meta, progress=progress)
