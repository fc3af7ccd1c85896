"""One step-budgeted training run that survives a stopped machine: the benchmarks' long runs.

A benchmark that trains for hours (the budget curve, the chunk sweep on the arm pair, the pixel
policy, a head the package does not ship) calls :func:`train_steps`. The run trains for exactly
``steps`` optimiser steps into ``run`` (a folder in a cache, never the repository). Its resume state
(:mod:`coursekit.train_state`) lives beside it as ``.<run name>.state.pt`` and is rewritten about
every minute, so a killed run started again with the same arguments continues with the same bytes as
an uninterrupted one; the state is removed once the checkpoint is written. A step budget rather
than minutes keeps a result independent of what else shares the core.

A machine's cache does not outlive it, and a sweep of fifteen runs outlives a working day: a finished
run's evaluations (per-seed outcomes, a few kilobytes) are kept in the repository's ledger by
``python -m benchmarks.ledger`` and read from there first (:func:`evaluation_file`), so a row over
three training seeds can be recorded on a machine that trained none of them.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Callable

CACHE_ROOT = Path(os.environ.get("XDG_CACHE_HOME", "~/.cache")).expanduser() / "coursekit"
"""Where the long benchmarks keep their runs, evaluations and data sets: never the repository."""


LEDGER = Path(__file__).resolve().parent / "ledger"
"""Finished runs' evaluations kept in the repository: ``LEDGER / <benchmark cache> / <run> / <file>``."""


def cache_dir(name: str) -> Path:
    """``CACHE_ROOT / name`` (not created): one benchmark's runs, or ``data`` for the data sets they share."""
    return CACHE_ROOT / name


def run_slug(name: str) -> str:
    """A variant's display name as a folder name: "ACT k=100 without CVAE" -> "act-k-100-without-cvae"."""
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def state_path(run: Path) -> Path:
    """The resume state of ``run``: ``run.parent / ".<run.name>.state.pt"``."""
    return run.parent / f".{run.name}.state.pt"


def kept_file(run: Path, name: str, ledger: Path | None = None) -> Path:
    """Where the ledger keeps ``run``'s evaluation file ``name`` (whether or not it is kept yet).

    The ledger mirrors the cache: ``run = ~/.cache/coursekit/act_chunks/act-k-10_seed0_s7000`` is kept
    as ``LEDGER / "act_chunks" / "act-k-10_seed0_s7000"`` (``ledger``: another root, default :data:`LEDGER`).
    """
    return (LEDGER if ledger is None else ledger) / run.parent.name / run.name / name


def evaluation_file(run: Path, name: str, ledger: Path | None = None) -> Path:
    """Where ``run``'s evaluation file ``name`` is read: the ledger's kept copy if there is one, else ``run / name``.

    A missing evaluation is made in the cache.
    """
    kept = kept_file(run, name, ledger)
    return kept if kept.is_file() else run / name


def is_trained(run: Path) -> bool:
    """True when ``run`` holds a finished checkpoint (its config written and no resume state left)."""
    return (run / "config.json").is_file() and not state_path(run).is_file()


def train_steps(policy, batches, recipe: dict, run: Path, steps: int, seed: int, threads: int = 1,
                dataset_meta: dict | None = None, progress: bool = False):
    """Train ``policy`` on ``batches`` for ``steps`` steps of ``recipe`` into ``run``; returns the trained policy.

    ``recipe`` is a policy class's named recipe (``make_policy`` returns it); ``seed`` seeds the
    batches and the run (the caller seeds the weights when it builds ``policy``); ``threads`` is
    the torch thread count (one run per core). The returned policy carries the EMA weights, which
    is what the checkpoint in ``run`` holds.
    """
    import torch

    from coursekit.checkpoint import CheckpointSaver
    from coursekit.train import TrainConfig, train

    run.parent.mkdir(parents=True, exist_ok=True)
    state = state_path(run)
    torch.manual_seed(seed)
    config = TrainConfig(**{**recipe, "max_steps": steps, "seed": seed, "num_threads": threads,
                            "progress": progress, "checkpoint_every_minutes": None})
    result = train(policy, batches, config, callbacks=[CheckpointSaver(run, dataset_meta=dataset_meta)],
                   state_file=state)
    state.unlink(missing_ok=True)
    return result.policy


def load_or_train(run: Path, build: Callable[[], tuple], steps: int, seed: int, threads: int = 1,
                  dataset_meta: dict | None = None):
    """The policy of ``run``: its checkpoint when finished, else ``build()`` trained (or resumed) for ``steps``.

    ``build`` returns ``(policy, batches, recipe)`` as :func:`coursekit.policies.make_policy` does; it is
    only called when there is something to train, so a finished run costs no data loading or model
    building beyond the checkpoint's.
    """
    from coursekit.checkpoint import load_checkpoint

    if is_trained(run):
        return load_checkpoint(run, device="cpu")
    policy, batches, recipe = build()
    return train_steps(policy, batches, recipe, run, steps, seed, threads, dataset_meta)
