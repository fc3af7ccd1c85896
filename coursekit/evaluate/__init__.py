"""Closed-loop evaluation: one generic rollout, one adapter per task.

    closed_loop.py  rollout (B envs in lock-step, any executor), evaluate (any policy on any task), TaskAdapter
    result.py    EvalResult, held-out seeds (100000 + i), the demonstration-seed overlap check
    pusht.py     PushTAdapter, evaluate_pusht (Diffusion Policy's mean-of-max protocol)
    aloha.py     ArmPairAdapter, evaluate_aloha (ACT's stage rates + strict final-state success)
    tasks.py     TASKS, make_adapter(task, policy), task_of(policy, dataset_meta)
    behaviour.py stalled_steps / still_steps (PushT hesitation), rms_jerk (smoothness of executed actions)
    delayed.py   evaluate_delayed (chapter 11: any strategy under an inference delay d), smoothness, chunk latency
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
    "PushTAdapter": "coursekit.evaluate.pusht",
    "evaluate_pusht": "coursekit.evaluate.pusht",
    "ArmPairAdapter": "coursekit.evaluate.aloha",
    "evaluate_aloha": "coursekit.evaluate.aloha",
    "ALOHA_TASKS": "coursekit.evaluate.aloha",
    "STATE_COLUMNS": "coursekit.evaluate.aloha",
    "TASKS": "coursekit.evaluate.tasks",
    "make_adapter": "coursekit.evaluate.tasks",
    "stalled_steps": "coursekit.evaluate.behaviour",
    "still_steps": "coursekit.evaluate.behaviour",
    "rms_jerk": "coursekit.evaluate.behaviour",
    "evaluate_delayed": "coursekit.evaluate.delayed",
    "smoothness": "coursekit.evaluate.delayed",
    "chunk_latency_ms": "coursekit.evaluate.delayed",
    "latency_delay": "coursekit.evaluate.delayed",
    "STRATEGIES": "coursekit.evaluate.delayed",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)
