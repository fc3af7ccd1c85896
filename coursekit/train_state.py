"""Mid-run resume for :func:`coursekit.train.train`: a killed run continues with exactly the same bytes.

A long experiment (the budget curves, a head trained for an hour on one core) must survive a
machine that stops it. A checkpoint is not enough to continue the SAME run: it holds only the
(EMA) weights. The resume state holds everything the remaining steps depend on:

    step, raw weights, EMA weights and decay, AdamW moments, torch's global RNG (the diffusion
    noise and timesteps, crops), the batcher's shuffling state (generator, epoch order, position),
    the run's counters, history and elapsed seconds

and the training config it belongs to (a state written under another config is refused, naming
the fields that differ). Only step budgets resume: with a minutes budget the number of steps
depends on the machine's speed, so "the same run" is not defined.

The file is written with :func:`coursekit.atomic.atomic_path`: a kill during a write leaves the
previous state, and the next write removes the killed one's temporary.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import torch

from coursekit.atomic import atomic_path
from coursekit.config import config_to_dict

STATE_EVERY_S = 60.0
"""Most seconds between two writes of the resume state (checked at every log point); a run with
periodic checkpoints more often than that (``checkpoint_every_minutes``) writes it as often."""
FORMAT = "coursekit-train-state-1"


class TrainState:
    """Save and restore everything a run's remaining steps depend on (see the module docstring)."""

    def __init__(self, path: str | os.PathLike, config: Any, policy: Any, optimizer: torch.optim.Optimizer,
                 ema: Any, batches: Any, run: Any) -> None:
        if config.max_steps is None or config.minutes is not None:
            raise ValueError(f"a resumable run needs a step budget only (max_steps), got max_steps={config.max_steps!r}, "
                             f"minutes={config.minutes!r}: a time budget trains a machine-dependent number of steps")
        if not (callable(getattr(batches, "state_dict", None)) and callable(getattr(batches, "load_state_dict", None))):
            raise ValueError(f"a resumable run needs a batcher with state_dict()/load_state_dict() "
                             f"(WindowBatcher, ChunkBatcher), got {type(batches).__name__}")
        self.path = Path(path)
        self.config, self.policy, self.optimizer, self.ema, self.batches, self.run = config, policy, optimizer, ema, batches, run
        self.last_save = time.perf_counter()
        minutes = getattr(config, "checkpoint_every_minutes", None)
        self.every_s = STATE_EVERY_S if minutes is None else min(STATE_EVERY_S, 60.0 * minutes)

    def _payload(self, now: float) -> dict[str, Any]:
        run = self.run
        return {"format": FORMAT, "train_config": config_to_dict(self.config), "step": run.step,
                "policy": self.policy.state_dict(), "optimizer": self.optimizer.state_dict(),
                "ema": None if self.ema is None else {"model": self.ema.model.state_dict(), "decay": self.ema.decay},
                "torch_rng": torch.get_rng_state(), "batches": self.batches.state_dict(),
                "run": {"samples": run.samples, "history": run.history, "last_loss": run.last_loss,
                        "elapsed_s": now - run.start}}

    def save(self, now: float | None = None) -> None:
        """Write the state atomically (called at log points, right after a log row closed)."""
        now = time.perf_counter() if now is None else now
        with atomic_path(self.path) as tmp:  # a kill mid-write leaves the previous state (and no stray temporary)
            torch.save(self._payload(now), tmp)
        self.last_save = now

    def maybe_save(self, now: float) -> None:
        """Save when ``every_s`` seconds have passed since the last save (or the last step is done)."""
        if now - self.last_save >= self.every_s or self.run.step >= self.config.max_steps:
            self.save(now)

    @staticmethod
    def saved_step(path: str | os.PathLike) -> int:
        """The step a resume state file was written at (ValueError naming the file if it is not one)."""
        return int(_read(Path(path))["step"])

    def resume(self) -> bool:
        """Restore the saved state if the file exists (True), after checking it belongs to this run."""
        if not self.path.is_file():
            return False
        state = _read(self.path)
        mine = config_to_dict(self.config)
        differ = sorted(k for k in set(mine) | set(state["train_config"])
                        if k not in ("progress", "checkpoint_every_minutes") and mine.get(k) != state["train_config"].get(k))
        if differ:
            raise ValueError(f"the resume state {str(self.path)!r} was written under another training config "
                             f"(differs in {differ}); delete it or train into a new folder")
        self._restore(state)
        return True

    def _restore(self, state: dict[str, Any]) -> None:
        self.policy.load_state_dict(state["policy"])
        base_lrs = [g["lr"] for g in self.optimizer.param_groups]  # the peak LRs: the loop scales them per step
        self.optimizer.load_state_dict(state["optimizer"])
        for g, lr in zip(self.optimizer.param_groups, base_lrs):
            g["lr"] = lr
        if self.ema is not None:
            self.ema.model.load_state_dict(state["ema"]["model"])
            self.ema.decay = state["ema"]["decay"]
        torch.set_rng_state(state["torch_rng"])
        self.batches.load_state_dict(state["batches"])
        run, saved = self.run, state["run"]
        run.step, run.samples, run.history = int(state["step"]), int(saved["samples"]), list(saved["history"])
        run.last_loss = float(saved["last_loss"])
        run.start = run.last_log_t = time.perf_counter() - float(saved["elapsed_s"])


def _read(path: Path) -> dict[str, Any]:
    """Load a resume state file, refusing a truncated or foreign one by name (never train on garbage)."""
    try:
        state = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:
        raise ValueError(f"cannot read the resume state {str(path)!r}: {exc}") from exc
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise ValueError(f"{str(path)!r} is not a coursekit training state (format {FORMAT!r})")
    return state
