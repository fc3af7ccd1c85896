"""Closed-loop evaluation: one generic rollout, one adapter per task.

    closed_loop.py  rollout (B envs in lock-step, any executor), evaluate (any policy on any task), TaskAdapter
    result.py    EvalResult, held-out seeds (100000 + i), the demonstration-seed overlap check
    tasks.py     RecordAdapter (any task, from its record in coursekit.tasks), make_adapter, task_of
    pusht.py     evaluate_pusht (Diffusion Policy's mean-of-max protocol)
    aloha.py     evaluate_aloha (ACT's stage rates + strict final-state success)
    behaviour.py stalled_steps / still_steps (PushT hesitation), jerk / rms_jerk / smoothness (of executed actions)
    latency.py   chunk_latency_ms (ms per chunk on this CPU), latency_delay (the delay d it means at a task's rate)

Chapter 11's delayed execution is an executor choice of ``evaluate`` (``executor_cls`` from
``coursekit.execution.rtc.STRATEGIES``, ``executor_options={"delay": d}``), not another loop.
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "EVAL_SEED_START": "coursekit.evaluate.result",
    "EvalResult": "coursekit.evaluate.result",
    "heldout_seeds": "coursekit.evaluate.result",
    "check_seeds_disjoint": "coursekit.evaluate.result",
    "rollout": "coursekit.evaluate.closed_loop:rollout",
    "evaluate": "coursekit.evaluate.closed_loop:evaluate",
    "TaskAdapter": "coursekit.evaluate.closed_loop",
    "evaluate_pusht": "coursekit.evaluate.pusht",
    "evaluate_aloha": "coursekit.evaluate.aloha",
    "RecordAdapter": "coursekit.evaluate.tasks",
    "make_adapter": "coursekit.evaluate.tasks",
    "task_of": "coursekit.evaluate.tasks",
    "stalled_steps": "coursekit.evaluate.behaviour",
    "still_steps": "coursekit.evaluate.behaviour",
    "jerk": "coursekit.evaluate.behaviour",
    "rms_jerk": "coursekit.evaluate.behaviour",
    "smoothness": "coursekit.evaluate.behaviour",
    "chunk_latency_ms": "coursekit.evaluate.latency",
    "latency_delay": "coursekit.evaluate.latency",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)
