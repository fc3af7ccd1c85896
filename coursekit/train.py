"""The trainer, shared by every chunk policy: AdamW, warm-up + cosine LR, EMA weights, a time budget.

It knows nothing about diffusion and writes no file: it draws batches from an iterable, calls
``policy.compute_loss(batch)["loss"]``, steps the optimiser and updates the EMA copy; whoever
wants a record passes callbacks (:class:`TrainCallback`): ``on_log(record)`` every
``log_every`` steps (a metrics table, a live loss curve) and ``on_checkpoint(policy, summary)``
every ``checkpoint_every_minutes`` and at the end (``coursekit.checkpoint.CheckpointSaver``
writes the checkpoint). Defaults follow Diffusion Policy's training recipe (Chi et al. 2023, App. A and the
reference config): AdamW(lr 1e-4, betas (0.95, 0.999), weight decay 1e-6), 500 warm-up steps
then cosine decay stepped per batch, batch 256, EMA with decay ``1 - (1 + step)^-0.75`` capped
at 0.9999. Each policy class names its recipes (``recipes``: "paper", "cpu"); ACT's differ
(constant LR, no EMA, ...).

A run ends at ``max_steps`` or after ``minutes`` of wall-clock time, whichever comes first. With
only a time budget the cosine schedule runs on elapsed time (the fraction of the budget used),
so the LR still reaches ~0 when time is up however fast the machine is; with ``max_steps`` the
schedule is the usual step-based one and the run is bit-for-bit deterministic on a CPU.
"""

from __future__ import annotations

import copy
import math
import os
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import torch
from tqdm.auto import tqdm

from coursekit.config import config_to_dict

LR_SCHEDULES = ("cosine", "constant")


@dataclass
class TrainConfig:
    """Optimiser, schedule, EMA and budget settings of one training run."""

    lr: float = 1e-4
    """Peak learning rate of AdamW."""
    betas: tuple[float, float] = (0.95, 0.999)
    """AdamW betas (Diffusion Policy uses beta1 = 0.95)."""
    weight_decay: float = 1e-6
    """AdamW decoupled weight decay."""
    lr_schedule: str = "cosine"
    """'cosine' (warm-up then cosine to 0) or 'constant' (warm-up then flat; ACT)."""
    warmup_steps: int = 500
    """Linear warm-up length in optimiser steps (LR stepped per batch)."""
    batch_size: int = 256
    """Samples per optimiser step asked of the caller's batcher (the summary counts the rows it gave)."""
    max_steps: int | None = None
    """Stop after this many optimiser steps (None: time budget only)."""
    minutes: float | None = None
    """Stop after this much wall-clock time (None: step budget only)."""
    ema: bool = True
    """Keep an exponential moving average of the weights and return it as the trained policy."""
    ema_power: float = 0.75
    """EMA warm-up power: decay = 1 - (1 + step)^-power."""
    ema_max_decay: float = 0.9999
    """Cap of the EMA decay."""
    grad_clip_norm: float | None = None
    """Clip the gradient norm to this value (None: no clipping, as in Diffusion Policy)."""
    seed: int = 0
    """Seeds torch's global generator at the start (noise, timesteps, crops); batches are seeded by their batcher."""
    num_threads: int | None = None
    """torch.set_num_threads for the run (restored afterwards); None leaves it alone."""
    checkpoint_every_minutes: float | None = 5.0
    """Hand the (EMA) policy to the callbacks' on_checkpoint this often (None: only at the end)."""
    log_every: int = 50
    """Record mean loss / LR / throughput (history and on_log) every this many steps."""
    progress: bool = True
    """Show a tqdm progress bar."""

    @classmethod
    def recipe(cls, name: str, policy_type: str = "diffusion", **overrides: Any) -> TrainConfig:
        """The named recipe of a policy type ("paper" or "cpu"; see each class's ``recipes``).

        Diffusion Policy's "paper" is the defaults above (lr 1e-4, batch 256); its "cpu" (lr 5e-4,
        batch 128) is a measured departure for a ~20-minute CPU budget (reasons and numbers beside
        ``UNetChunkPolicy.recipes``); ACT's are beside ``ACTPolicy.recipes``. ``overrides`` set any
        other field (a budget: ``minutes=`` and/or ``max_steps=``).
        """
        from coursekit.policies import get_policy_class

        recipes = get_policy_class(policy_type).recipes
        if name not in recipes:
            raise ValueError(f"unknown training recipe {name!r} for {policy_type!r}; expected one of {sorted(recipes)}")
        return cls(**{**recipes[name], **overrides})

    def __post_init__(self) -> None:
        if self.max_steps is None and self.minutes is None:
            raise ValueError("TrainConfig needs max_steps or minutes (or both); got neither")
        if self.max_steps is not None and (not isinstance(self.max_steps, int) or self.max_steps < 1):
            raise ValueError(f"max_steps must be a positive int or None, got {self.max_steps!r}")
        if self.minutes is not None and not self.minutes > 0:
            raise ValueError(f"minutes must be > 0 or None, got {self.minutes!r}")
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr!r}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"lr_schedule must be one of {LR_SCHEDULES}, got {self.lr_schedule!r}")
        if not isinstance(self.warmup_steps, int) or self.warmup_steps < 0:
            raise ValueError(f"warmup_steps must be an int >= 0, got {self.warmup_steps!r}")
        if not isinstance(self.batch_size, int) or self.batch_size < 1:
            raise ValueError(f"batch_size must be a positive int, got {self.batch_size!r}")
        if not 0.0 <= self.ema_max_decay < 1.0 or not self.ema_power > 0:
            raise ValueError(f"need 0 <= ema_max_decay < 1 and ema_power > 0, got {self.ema_max_decay!r}, {self.ema_power!r}")
        if self.log_every < 1:
            raise ValueError(f"log_every must be >= 1, got {self.log_every!r}")


def lr_factor(step: int, warmup_steps: int, progress: float, schedule: str = "cosine") -> float:
    """Multiplier of the peak LR at optimiser step ``step`` (0-based).

    Warm-up: ``step / warmup_steps`` for step < warmup_steps. After it, ``progress`` in [0, 1] is the
    fraction of the post-warm-up budget used: cosine gives ``0.5 (1 + cos(pi progress))``,
    constant gives 1. With a step budget progress = (step - warmup) / (max_steps - warmup), which
    equals diffusers' ``get_cosine_schedule_with_warmup``.
    """
    if step < warmup_steps:
        return step / max(1, warmup_steps)
    if schedule == "constant":
        return 1.0
    return max(0.0, 0.5 * (1.0 + math.cos(math.pi * min(max(progress, 0.0), 1.0))))


def ema_decay(step: int, power: float = 0.75, max_decay: float = 0.9999) -> float:
    """EMA decay after optimiser step ``step`` (0-based): min(max_decay, 1 - (1 + step)^-power).

    Step 0 gives 0 (the average starts as a copy of the weights); the decay then rises towards
    the cap, so early, poor weights are forgotten quickly (Diffusion Policy's EMAModel warm-up).
    """
    return min(max_decay, max(0.0, 1.0 - (1.0 + step) ** -power))


class EMA:
    """An exponential moving average copy of a module: ema <- decay * ema + (1 - decay) * weights."""

    def __init__(self, model: torch.nn.Module, power: float = 0.75, max_decay: float = 0.9999):
        self.model = copy.deepcopy(model).eval().requires_grad_(False)
        self.power, self.max_decay = power, max_decay
        self.decay = 0.0

    @torch.no_grad()
    def update(self, model: torch.nn.Module, step: int) -> None:
        """Blend ``model``'s current weights in, with the decay of optimiser step ``step``."""
        self.decay = ema_decay(step, self.power, self.max_decay)
        ema_params = list(self.model.parameters())
        params = [p.detach() for p in model.parameters()]
        torch._foreach_lerp_(ema_params, params, 1.0 - self.decay)  # ema += (1 - decay) (p - ema)
        for eb, b in zip(self.model.buffers(), model.buffers()):
            eb.copy_(b)  # buffers (e.g. normalisation statistics) are copied, not averaged


@dataclass
class TrainResult:
    """What a run produced.

    Attributes:
        policy: the policy to evaluate (the EMA copy when ``ema`` is on, else the trained one).
        raw_policy: the optimised (non-averaged) policy.
        history: one dict per ``log_every`` steps: step, seconds, lr, samples_per_s, mean of each loss key.
        summary: steps, samples, seconds, samples_per_s, final_loss, loss_curve ([step, seconds, mean loss]
            per history row), config, ... (stored in checkpoints).
    """

    policy: Any
    raw_policy: Any
    history: list[dict[str, float]] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)


def make_optimizer(policy: torch.nn.Module, config: TrainConfig) -> torch.optim.Optimizer:
    """AdamW (fused kernel where available) over ``policy.optimizer_param_groups(lr, wd)`` if the policy
    defines it, else all parameters that require gradients."""
    groups = (policy.optimizer_param_groups(config.lr, config.weight_decay)
              if hasattr(policy, "optimizer_param_groups") else [p for p in policy.parameters() if p.requires_grad])
    kwargs = {"lr": config.lr, "betas": config.betas, "weight_decay": config.weight_decay}
    try:
        # The fused kernel updates all tensors in one pass: measured 4 ms vs 22 ms per step for the
        # 4.5 M-parameter U-Net on one CPU core (the default for-loop); same maths.
        return torch.optim.AdamW(groups, fused=True, **kwargs)
    except (RuntimeError, ValueError):  # a device/dtype without the fused kernel
        return torch.optim.AdamW(groups, foreach=True, **kwargs)


class TrainCallback(Protocol):
    """What a training callback may define (each method is optional; duck-typed).

    ``on_log(record)``: every ``log_every`` steps (and at the last step) with a record holding
    exactly ``step``, ``loss`` (mean since the last record), ``lr``, ``samples_per_s``, ``wall_s``.
    ``on_checkpoint(policy, summary)``: every ``checkpoint_every_minutes`` with the (EMA) policy
    and ``summary["complete"] = False``, and once at the end with the final policy and the full
    summary (``complete = True``). A callback must not change the policy.
    """

    def on_log(self, record: Mapping[str, float]) -> None: ...

    def on_checkpoint(self, policy: Any, summary: Mapping[str, Any]) -> None: ...


def _notify(callbacks: Sequence[Any], method: str, *args: Any) -> None:
    for cb in callbacks:
        fn = getattr(cb, method, None)
        if fn is not None:
            fn(*args)


def _batch_rows(batch: Any, default: int) -> int:
    """Samples in one batch: the rows of its "action" (B, Tp, Da) (the batch contract), else ``default``."""
    action = batch.get("action") if isinstance(batch, Mapping) else None
    return int(action.shape[0]) if hasattr(action, "shape") and len(action.shape) else default


def train(policy: Any, batches: Iterable[dict[str, Any]], config: TrainConfig, *,
          callbacks: Sequence[TrainCallback] = (), init_from: dict[str, Any] | None = None,
          state_file: str | os.PathLike | None = None) -> TrainResult:
    """Train ``policy`` in place on ``batches`` (an endless iterable of batch dicts) under ``config``.

    Args:
        policy: a ChunkPolicy with fitted normalisers (``compute_loss(batch)["loss"]``).
        batches: e.g. the batcher from :func:`coursekit.policies.make_policy` (seeded on its own).
        config: the :class:`TrainConfig`.
        callbacks: :class:`TrainCallback` objects (e.g. ``CheckpointSaver(out_dir)``, ``MetricsLog(run_dir)``).
        init_from: provenance of the weights ``policy`` starts from when this run continues an
            earlier one (``coursekit.checkpoint.warm_start``); stored as ``summary["init_from"]``
            so a checkpoint states its whole training, not only the last segment.
        state_file: resume file (step budgets only; see :mod:`coursekit.train_state`): if it exists
            the run continues from it exactly (the same bytes as an uninterrupted run); it is
            rewritten at the first log point once ``STATE_EVERY_S`` seconds (or
            ``checkpoint_every_minutes``, if shorter) have passed since the last write, so a killed
            run loses at most that much work plus ``log_every`` steps.
    """
    threads_before = torch.get_num_threads()
    if config.num_threads is not None:
        torch.set_num_threads(config.num_threads)
    threads_used = torch.get_num_threads()
    torch.manual_seed(config.seed)
    policy.train()
    optimizer = make_optimizer(policy, config)
    ema = EMA(policy, config.ema_power, config.ema_max_decay) if config.ema else None
    run = _RunRecord(policy, ema, config, init_from, threads_used)
    saver = None
    if state_file is not None:
        from coursekit.train_state import TrainState

        saver = TrainState(state_file, config, policy, optimizer, ema, batches, run)
        saver.resume()
    budget = _Budget(config, run.start)
    bar = tqdm(total=config.max_steps if config.max_steps is not None else int(budget.seconds),
               unit="step" if config.max_steps is not None else "s", disable=not config.progress,
               desc=f"train {getattr(policy, 'policy_type', '')}".strip(), dynamic_ncols=True)
    try:
        bar.update(run.step if config.max_steps is not None else 0)  # a resumed run starts where it stopped
        _optimise(policy, iter(batches), optimizer, ema, budget, run, bar, callbacks, saver)
        bar.total = bar.n  # the budget is used up: end full and green (a time bar stops a second short)
    finally:
        bar.close()
        if config.num_threads is not None:
            torch.set_num_threads(threads_before)

    seconds = time.perf_counter() - run.start
    if run.step == 0:  # never hand an untrained policy to the checkpoint writer as if it were trained
        raise ValueError(f"the budget ended before the first optimiser step (minutes={config.minutes!r}); nothing was "
                         f"trained, so no checkpoint is written: give a budget of at least one step")
    final = ema.model if ema else policy
    final.eval()
    result = TrainResult(policy=final, raw_policy=policy, history=run.history,
                         summary={**run.summary(seconds), "complete": True})
    _notify(callbacks, "on_checkpoint", final, result.summary)
    return result


def _optimise(policy: Any, batch_iter: Iterator[dict[str, Any]], optimizer: torch.optim.Optimizer, ema: EMA | None,
              budget: _Budget, run: _RunRecord, bar: Any, callbacks: Sequence[Any], saver: Any = None) -> None:
    """The training loop: set the step's LR, take one optimiser step, log and checkpoint, until the budget ends."""
    config = run.config
    base_lrs = [g["lr"] for g in optimizer.param_groups]
    last_ckpt = run.start
    while not budget.spent(run.step, now := time.perf_counter()):
        factor = budget.lr_factor(run.step, now)
        for g, base in zip(optimizer.param_groups, base_lrs):
            g["lr"] = base * factor
        batch = next(batch_iter)
        run.add(batch, _optimiser_step(policy, optimizer, ema, batch, run.step, config))

        now = time.perf_counter()
        if run.step % config.log_every == 0 or (config.max_steps is not None and run.step == config.max_steps):
            row = run.log(now, base_lrs[0] * factor)
            bar.set_postfix(loss=f"{row['loss']:.4f}", lr=f"{row['lr']:.1e}", sps=f"{row['samples_per_s']:.0f}")
            _notify(callbacks, "on_log", {"step": run.step, "loss": row["loss"], "lr": row["lr"],
                                          "samples_per_s": row["samples_per_s"], "wall_s": row["seconds"]})
            if saver is not None:  # after the log row: a saved state's step is always in the metrics table
                saver.maybe_save(now)
        bar.update(1 if config.max_steps is not None else int(now - run.start) - bar.n)
        if (callbacks and config.checkpoint_every_minutes is not None
                and now - last_ckpt >= 60.0 * config.checkpoint_every_minutes):
            _notify(callbacks, "on_checkpoint", ema.model if ema else policy,
                    {**run.summary(now - run.start), "complete": False})
            last_ckpt = time.perf_counter()


def _optimiser_step(policy: Any, optimizer: torch.optim.Optimizer, ema: EMA | None, batch: dict[str, Any],
                    step: int, config: TrainConfig) -> dict[str, Any]:
    """One AdamW step on ``batch`` (loss, backward, optional clipping, EMA update); returns ``compute_loss``'s dict."""
    out = policy.compute_loss(batch)
    loss = out["loss"]
    if not torch.isfinite(loss):
        raise ValueError(f"training loss became {loss.item()} at step {step}; check the data and the LR ({config.lr})")
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if config.grad_clip_norm is not None:
        torch.nn.utils.clip_grad_norm_(policy.parameters(), config.grad_clip_norm)
    optimizer.step()
    if ema is not None:
        ema.update(policy, step)
    return out


class _Budget:
    """The stop rule (``max_steps`` and/or ``minutes``) and the LR schedule's progress through that budget."""

    def __init__(self, config: TrainConfig, start: float) -> None:
        self.config, self.start = config, start
        self.seconds = None if config.minutes is None else 60.0 * config.minutes
        self.warm_end_t: float | None = None  # when warm-up ended (a time budget's cosine starts there)

    def spent(self, step: int, now: float) -> bool:
        """True once ``step`` optimiser steps are done or the wall-clock budget is used up."""
        if self.config.max_steps is not None and step >= self.config.max_steps:
            return True
        return self.seconds is not None and now - self.start >= self.seconds

    def lr_factor(self, step: int, now: float) -> float:
        """LR multiplier for ``step``: warm-up by steps, then cosine over the budget used so far."""
        config = self.config
        if step >= config.warmup_steps and self.warm_end_t is None:
            self.warm_end_t = now
        progress = 0.0
        if config.max_steps is not None:
            progress = (step - config.warmup_steps) / max(1, config.max_steps - config.warmup_steps)
        if self.seconds is not None and self.warm_end_t is not None:
            remaining = max(1e-9, self.seconds - (self.warm_end_t - self.start))
            progress = max(progress, (now - self.warm_end_t) / remaining)
        return lr_factor(step, config.warmup_steps, progress, config.lr_schedule)


class _RunRecord:
    """What a run has done so far: steps, samples, the mean losses of each ``log_every`` period, its summary."""

    def __init__(self, policy: Any, ema: EMA | None, config: TrainConfig, init_from: dict[str, Any] | None,
                 threads_used: int) -> None:
        self.policy, self.ema, self.config = policy, ema, config
        self.init_from, self.threads_used = init_from, threads_used
        self.history: list[dict[str, float]] = []
        self.sums: dict[str, float] = {}
        self.step, self.n_logged, self.last_loss = 0, 0, float("nan")
        self.samples, self.logged_samples = 0, 0  # rows actually trained on (a batcher cuts a batch to the data it has)
        self.start = self.last_log_t = time.perf_counter()

    def add(self, batch: Any, out: dict[str, Any]) -> None:
        """Count one optimiser step on ``batch`` and its ``compute_loss`` outputs ``out``."""
        self.step += 1
        rows = _batch_rows(batch, self.config.batch_size)
        self.samples, self.logged_samples = self.samples + rows, self.logged_samples + rows
        self.last_loss = float(out["loss"].detach())
        for k, v in out.items():
            self.sums[k] = self.sums.get(k, 0.0) + float(v.detach() if torch.is_tensor(v) else v)
        self.n_logged += 1

    def log(self, now: float, lr: float) -> dict[str, float]:
        """Close the log period: append (and return) its history row of means, then start the next."""
        row = {"step": self.step, "seconds": round(now - self.start, 3), "lr": lr,
               "samples_per_s": self.logged_samples / max(now - self.last_log_t, 1e-9),
               **{k: v / self.n_logged for k, v in self.sums.items()}}
        self.history.append(row)
        self.sums, self.n_logged, self.logged_samples, self.last_log_t = {}, 0, 0, now
        return row

    def summary(self, seconds: float) -> dict[str, Any]:
        """The run's summary after ``seconds`` (stored in checkpoints; see :class:`TrainResult`)."""
        return {"steps": self.step, "samples": self.samples, "seconds": round(seconds, 2),
                "samples_per_s": round(self.samples / max(seconds, 1e-9), 1),
                "final_loss": self.last_loss, "ema_decay": self.ema.decay if self.ema else None,
                "train_config": config_to_dict(self.config), "torch_threads": self.threads_used,
                "loss_curve": [[h["step"], round(h["seconds"], 1), round(h["loss"], 5)] for h in self.history],
                "device": str(next(self.policy.parameters()).device),
                **({"init_from": self.init_from} if self.init_from is not None else {})}
