"""What one chunk costs on this CPU, and the inference delay d it means at a task's control rate (§10.4).

    ms = chunk_latency_ms(policy, "pusht")          # median wall-clock ms per chunk, batch 1
    d = latency_delay(ms, "pusht")                  # ceil(latency x control rate) control steps

The delay is then an executor option of :func:`coursekit.evaluate.closed_loop.evaluate`
(chapter 11: ``executor_options={"delay": d}``). ``guided=True`` times real-time chunking's
guided sampler instead, which adds a backward pass through the network at every step.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from coursekit.execution.delay import delay_steps


def chunk_latency_ms(policy: Any, task: str, *, sampling: Mapping[str, Any] | None = None, repeats: int = 5,
                     guided: bool = False, seed: int = 0) -> float:
    """Median milliseconds for one chunk (batch 1) on this machine, from a real first observation.

    ``guided``: time RTC's guided sampler (``policy.predict_inpainted``) instead.
    """
    import torch

    from coursekit.evaluate.tasks import make_adapter
    from coursekit.execution.receding import stack_history

    sampling = dict(sampling or {})
    adapter = make_adapter(task, policy)
    env = adapter.make_env(10)
    obs, _ = env.reset(seed=200000 + int(seed))  # a validation seed
    env.close()
    history = stack_history([adapter.obs_fn([obs])] * policy.execution_spec().n_obs_steps)  # (1, To, ...)
    gen = torch.Generator().manual_seed(int(seed))
    if guided:
        n = policy.execution_spec().usable_horizon
        target, weights = np.zeros((1, n, policy.config.action_dim)), np.linspace(1.0, 0.0, n)

        def call() -> Any:
            return policy.predict_inpainted(history, target, weights, generator=gen, **sampling)
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
