"""Evaluation under inference delay (chapter 11): any chunk policy, any strategy, any d, any task.

    evaluate_delayed(policy, "pusht", "rtc", delay=2, seeds=heldout_seeds(50))

runs the generic closed-loop :func:`~coursekit.evaluate.closed_loop.rollout` with a delay-aware executor
(:mod:`coursekit.execution.delay`, :mod:`coursekit.execution.rtc`). One torch generator, seeded
by ``seed``, draws every chunk's noise (guided or not), so a run is deterministic. Also here:
the chunk latency of a policy on this CPU (ms per chunk -> d at the task's control rate) and
the smoothness figures of an executed trajectory (largest step change, jump at chunk switches,
largest jerk).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from coursekit.execution.delay import AsyncChunking, DelayedEnsemble, Synchronous, delay_steps
from coursekit.execution.rtc import MAX_GUIDANCE, RealTimeChunking

STRATEGIES = {"sync": Synchronous, "async": AsyncChunking, "ensemble": DelayedEnsemble, "rtc": RealTimeChunking}
"""Strategy name -> executor class (all built with ``from_spec(predict_chunk, spec, delay=d)``)."""


def check_strategy(strategy: str, policy: Any) -> None:
    """Refuse an unknown strategy, or RTC for a policy without an iterative sampler (ValueError)."""
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy {strategy!r}; expected one of {list(STRATEGIES)}")
    if strategy == "rtc" and getattr(policy, "policy_type", "") not in ("diffusion", "flow"):
        raise ValueError(f"strategy 'rtc' inpaints during denoising/integration: it needs a diffusion or flow policy, "
                         f"not {getattr(policy, 'policy_type', type(policy).__name__)!r}")


def _adapter(policy: Any, task: str) -> Any:
    from coursekit.evaluate.tasks import make_adapter

    return make_adapter(task, policy)


def evaluate_delayed(policy: Any, task: str, strategy: str, delay: int, seeds: Sequence[int], *, seed: int = 0,
                     sampling: Mapping[str, Any] | None = None, max_steps: int | None = None, record: bool = False,
                     progress: bool = False, max_guidance: float = MAX_GUIDANCE, schedule: str = "exp",
                     prefix: str = "guide", dataset_meta: dict[str, Any] | None = None) -> Any:
    """Run ``policy`` on ``task`` from each of ``seeds`` with ``strategy`` under a delay of ``delay`` steps.

    Returns the task's :class:`~coursekit.evaluate.EvalResult`; ``info`` names the strategy, d,
    the sampling options and seed, the RTC calls and their time, and (``record=True``) the
    executor's chunk switch steps (``info["switches"]``) for :func:`smoothness`. RTC options:
    ``max_guidance`` (beta), ``schedule`` ("exp" or "hard") and ``prefix`` ("guide" or "replace",
    see :func:`coursekit.policies.inpainting.predict_inpainted`).
    """
    import torch

    from coursekit.evaluate.closed_loop import rollout
    from coursekit.evaluate.result import check_seeds_disjoint
    from coursekit.policies.inpainting import predict_inpainted

    check_strategy(strategy, policy)
    if isinstance(delay, bool) or not isinstance(delay, (int, np.integer)) or delay < 0:
        raise ValueError(f"delay (d) must be an integer >= 0 control steps, got {delay!r}")
    sampling = dict(sampling or {})
    policy.check_sampling(sampling)
    seeds = [int(s) for s in seeds]
    check_seeds_disjoint(seeds, dataset_meta)
    adapter = _adapter(policy, task)
    steps = adapter.max_steps if max_steps is None else int(max_steps)
    generator = torch.Generator().manual_seed(int(seed))
    policy.eval()
    policy.reset()
    guided = {"calls": 0, "seconds": 0.0}

    def predict_chunk(obs_history: Any) -> Any:
        return policy.predict_chunk(obs_history, generator=generator, **sampling)

    def guided_chunk(obs_history: Any, target: Any, weights: Any, frozen: int) -> Any:
        t0 = time.perf_counter()
        out = predict_inpainted(policy, obs_history, target, weights, frozen=frozen, generator=generator,
                                max_guidance=max_guidance, prefix=prefix, **sampling)
        guided["seconds"] += time.perf_counter() - t0
        guided["calls"] += 1
        return out

    made: list[Any] = []

    def factory(pc: Callable[[Any], Any]) -> Any:
        extra = {"predict_inpainted": guided_chunk, "schedule": schedule} if strategy == "rtc" else {}
        made.append(STRATEGIES[strategy].from_spec(pc, policy.execution_spec(), delay=int(delay), **extra))
        return made[-1]

    record = record or bool(getattr(adapter, "record_always", False))
    result = rollout(predict_chunk, lambda: adapter.make_env(steps), adapter.obs_fn, seeds, factory, max_steps=steps,
                     progress=progress, record=record, state_fn=adapter.state_fn,
                     desc=f"{policy.policy_type} {strategy} d={delay}")
    result.info.update({"policy_type": policy.policy_type, "task": task, "strategy": strategy, "delay": int(delay),
                        "max_steps": steps, "sampling_seed": int(seed), **sampling,
                        **({"max_guidance": max_guidance, "schedule": schedule, "prefix": prefix}
                           if strategy == "rtc" else {}),
                        "guided_calls": guided["calls"], "guided_seconds": round(guided["seconds"], 3),
                        **adapter.metrics(result)})
    if record:
        result.info["switches"] = list(made[-1].switches)
    return result


def smoothness(actions: np.ndarray, switches: Sequence[int] = ()) -> dict[str, float]:
    """Smoothness of executed actions (N, T, Da): means over episodes of per-episode figures.

    - max_step: max_t ||a_t - a_{t-1}|| (action units per step);
    - switch_jump: mean ||a_t - a_{t-1}|| over the chunk switch steps t > 0 (the discontinuity);
    - other_step: mean ||a_t - a_{t-1}|| over every other step (what a switch is compared with);
    - max_jerk: max_t ||a_t - 3 a_{t-1} + 3 a_{t-2} - a_{t-3}|| (third difference, units per step^3).
    """
    a = np.asarray(actions, dtype=np.float64)
    if a.ndim != 3 or a.shape[1] < 4:
        raise ValueError(f"actions must be (N, T >= 4, Da), got {a.shape}")
    step = np.linalg.norm(np.diff(a, axis=1), axis=-1)  # (N, T-1): step t -> index t - 1
    jerk = np.linalg.norm(np.diff(a, n=3, axis=1), axis=-1)  # (N, T-3)
    at_switch = np.zeros(step.shape[1], dtype=bool)
    idx = [t - 1 for t in switches if 0 < t < a.shape[1]]
    at_switch[idx] = True
    return {"max_step": float(step.max(axis=1).mean()),
            "switch_jump": float(step[:, at_switch].mean()) if at_switch.any() else float("nan"),
            "other_step": float(step[:, ~at_switch].mean()) if (~at_switch).any() else float("nan"),
            "max_jerk": float(jerk.max(axis=1).mean())}


def chunk_latency_ms(policy: Any, task: str, *, sampling: Mapping[str, Any] | None = None, repeats: int = 5,
                     guided: bool = False, seed: int = 0) -> float:
    """Median milliseconds for one chunk (batch 1) on this machine, from a real first observation.

    ``guided``: time RTC's guided sampler instead (a backward pass through the network per step).
    """
    import torch

    from coursekit.execution.receding import stack_history
    from coursekit.policies.inpainting import predict_inpainted

    sampling = dict(sampling or {})
    adapter = _adapter(policy, task)
    env = adapter.make_env(10)
    obs, _ = env.reset(seed=200000 + int(seed))  # a validation seed
    env.close()
    history = stack_history([adapter.obs_fn([obs])] * policy.execution_spec().n_obs_steps)  # (1, To, ...)
    gen = torch.Generator().manual_seed(int(seed))
    if guided:
        spec = policy.execution_spec()
        n = spec.horizon - (spec.n_obs_steps - 1)
        target, weights = np.zeros((1, n, policy.config.action_dim)), np.linspace(1.0, 0.0, n)

        def call() -> Any:
            return predict_inpainted(policy, history, target, weights, generator=gen, **sampling)
    else:
        def call() -> Any:
            return policy.predict_chunk(history, generator=gen, **sampling)
    call()  # warm-up
    times = []
    for _ in range(max(1, int(repeats))):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return 1000.0 * float(np.median(times))


def latency_delay(ms_per_chunk: float, task: str) -> int:
    """d at the task's control rate (its record's ``control_hz``) for a chunk latency in milliseconds."""
    from coursekit.tasks.registry import get_task

    return delay_steps(ms_per_chunk / 1000.0, get_task(task).control_hz)
