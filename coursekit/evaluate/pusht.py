"""``evaluate_pusht``: a policy on PushT by Diffusion Policy's protocol (``coursekit.tasks.pusht``).

Held-out initial states, ``PUSHT.max_steps`` (300) steps each; the score is the MEAN over episodes
of the MAXIMUM reward reached (reward = clip(coverage / 0.95, 0, 1)), and the success rate the
fraction of episodes whose coverage ever exceeds 0.95 (the episode then ends).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from coursekit.evaluate.closed_loop import evaluate
from coursekit.evaluate.result import EvalResult, heldout_seeds
from coursekit.evaluate.tasks import make_adapter
from coursekit.tasks.pusht import PUSHT


def evaluate_pusht(policy: Any, n_episodes: int = 50, seeds: Sequence[int] | None = None, max_steps: int | None = None,
                   sampler: str | None = None, num_inference_steps: int | None = None, seed: int = 0,
                   executor_cls: Any = None, executor_factory: Callable[[Callable[[Any], Any]], Any] | None = None,
                   dataset_meta: dict[str, Any] | None = None, progress: bool = True, record: bool = False) -> EvalResult:
    """Evaluate a PushT chunk policy by the paper's protocol (see module docstring).

    Args:
        policy: a ChunkPolicy (DiffusionPolicy, RegressionPolicy, ACT, ...) on PushT features.
        n_episodes, seeds: episodes to run; default seeds are :func:`heldout_seeds` (100000 + i).
        max_steps: steps per episode (default: the protocol's ``PUSHT.max_steps``).
        sampler, num_inference_steps: the diffusion sampler ("ddim"/"ddpm", steps); refused by
            policies that do not sample.
        seed: seeds the torch generator of the sampler's noise (the evaluation is deterministic).
        executor_cls: e.g. a student's RecedingHorizon class (built with ``from_spec``);
            executor_factory: full control instead.
        dataset_meta: demonstrations' meta (default: none); overlapping seeds are refused.
        record: keep states (N, T+1, 7) and actions (N, T, 2) for plots.
    """
    sampling = {k: v for k, v in (("sampler", sampler), ("num_inference_steps", num_inference_steps)) if v is not None}
    return evaluate(policy, make_adapter(PUSHT, policy), list(seeds) if seeds is not None else heldout_seeds(n_episodes),
                    max_steps=max_steps, sampling=sampling, seed=seed, executor_cls=executor_cls,
                    executor_factory=executor_factory, dataset_meta=dataset_meta, progress=progress, record=record)
