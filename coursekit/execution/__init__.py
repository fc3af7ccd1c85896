"""Executors: turn a chunk predictor (B, To, ...) -> (B, Tp, Da) into one action per step.

Every executor is built as ``cls.from_spec(predict_chunk, spec)`` from the policy's
:class:`ExecutionSpec` (:mod:`coursekit.execution.spec`, which also holds the To - 1 + Ta <= Tp
check), and has ``reset(obs (B, ...))`` and ``act(obs (B, ...)) -> (B, Da)``:

- :class:`RecedingHorizon` (Diffusion Policy): execute Ta actions of each chunk, then re-plan.
- :class:`TemporalEnsemble` (ACT): predict every step, average the overlapping chunks.
- Under an inference delay of d steps (:mod:`coursekit.execution.delay`, chapter 11):
  :class:`Synchronous`, :class:`AsyncChunking`, :class:`DelayedEnsemble` and
  :class:`RealTimeChunking` (:mod:`coursekit.execution.rtc`, which also names the four in
  ``STRATEGIES`` and holds RTC's guidance, shared by the diffusion and flow policies).

Classes load lazily (``coursekit.execution.receding`` needs neither torch nor numpy at import).
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "RecedingHorizon": "coursekit.execution.receding",
    "stack_history": "coursekit.execution.receding",
    "to_numpy": "coursekit.execution.receding",
    "TemporalEnsemble": "coursekit.execution.ensembling",
    "ExecutionSpec": "coursekit.execution.spec",
    "check_horizons": "coursekit.execution.spec",
    "delay_steps": "coursekit.execution.delay",
    "DelayedExecutor": "coursekit.execution.delay",
    "Synchronous": "coursekit.execution.delay",
    "AsyncChunking": "coursekit.execution.delay",
    "DelayedEnsemble": "coursekit.execution.delay",
    "RealTimeChunking": "coursekit.execution.rtc",
    "rtc_weights": "coursekit.execution.rtc",
    "STRATEGIES": "coursekit.execution.rtc",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)
