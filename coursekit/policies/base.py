"""What every chunk policy shares: the contract the trainer, executors and checkpoints rely on.

A policy is a ``torch.nn.Module`` with

- ``policy_type`` (class attribute, e.g. "diffusion") and ``config_class`` (its dataclass);
- ``__init__(config, normalizers=None)``: the only constructor the checkpoint loader calls;
- ``normalizers``: name -> normaliser (``MinMaxNormalizer`` / ``MeanStdNormalizer``), fitted on the
  training data and saved in the checkpoint's config.json (so a policy is usable on its own);
- ``compute_loss(batch) -> dict`` with key "loss" (a scalar tensor) plus float diagnostics;
  ``batch`` is in RAW units, the policy normalises it;
- ``predict_chunk(obs_history) -> (B, Tp, Da)`` raw actions from a raw (B, To, ...) history
  (an unbatched (To, ...) history gives (Tp, Da));
- ``reset()`` between episodes; ``make_executor(predict_chunk)`` builds its default executor.

The trainer owns the optimiser; the policy owns nothing but its weights and statistics.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from coursekit.data.normalize import MeanStdNormalizer, MinMaxNormalizer, normalizer_from_state

Normalizer = MinMaxNormalizer | MeanStdNormalizer


def normalizers_to_json(normalizers: Mapping[str, Normalizer]) -> dict[str, Any]:
    """{name: normaliser} -> {name: {"kind": ..., "state": {stat: list}}} (JSON-ready)."""
    return {name: {"kind": n.kind, "state": {k: np.asarray(v).tolist() for k, v in n.state_dict().items()}}
            for name, n in normalizers.items()}


def normalizers_from_json(data: Mapping[str, Any]) -> dict[str, Normalizer]:
    """Inverse of :func:`normalizers_to_json`; a malformed entry -> ValueError naming it."""
    out = {}
    for name, entry in data.items():
        try:
            out[name] = normalizer_from_state(entry["kind"], {k: np.asarray(v, dtype=np.float32) for k, v in entry["state"].items()})
        except (KeyError, TypeError) as exc:
            raise ValueError(f"normaliser {name!r} is malformed ({type(exc).__name__}: {exc}): {entry!r}") from exc
    return out


def as_float_tensor(x: Any, name: str, device: torch.device) -> torch.Tensor:
    """numpy/tensor -> float32 tensor on ``device``; NaN/inf -> ValueError naming ``name``."""
    t = torch.as_tensor(x)
    if t.dtype != torch.uint8:
        t = t.to(torch.float32)
        if not bool(torch.isfinite(t).all()):
            raise ValueError(f"{name} contains NaN or inf (shape {tuple(t.shape)})")
    return t.to(device)


class ChunkPolicy(nn.Module):
    """Base class: normalisers, device handling and the default executor. See module docstring."""

    policy_type: ClassVar[str] = ""
    config_class: ClassVar[type] = object

    def __init__(self, config: Any, normalizers: Mapping[str, Normalizer] | None = None):
        super().__init__()
        if not isinstance(config, self.config_class):
            raise ValueError(f"{type(self).__name__} needs a {self.config_class.__name__}, got {type(config).__name__}")
        self.config = config
        self.normalizers: dict[str, Normalizer] = dict(normalizers or {})

    # ---- statistics --------------------------------------------------------------------
    def set_normalizers(self, normalizers: Mapping[str, Normalizer]) -> None:
        """Install fitted normalisers (before training), checking their dimensions."""
        expected = self.normalizer_dims()
        for name, dim in expected.items():
            if name not in normalizers:
                raise ValueError(f"{type(self).__name__} needs a normaliser for {name!r}; got {sorted(normalizers)}")
            got = len(next(iter(normalizers[name].state_dict().values())))
            if got != dim:
                raise ValueError(f"normaliser {name!r} has {got} dimensions, the config says {dim}")
        self.normalizers = dict(normalizers)

    def normalizer_dims(self) -> dict[str, int]:
        """Which normalisers the policy needs and their dimension (overridden by subclasses)."""
        return {}

    def _require_normalizers(self) -> None:
        missing = sorted(set(self.normalizer_dims()) - set(self.normalizers))
        if missing:
            raise ValueError(f"{type(self).__name__} has no fitted normaliser for {missing}: call "
                             "set_normalizers(...) (or fit_normalizers) before training or predicting")

    # ---- inference helpers -------------------------------------------------------------
    @property
    def device(self) -> torch.device:
        return next(self.parameters()).device

    def reset(self) -> None:
        """Forget any per-episode state (none by default; executors hold the history)."""

    def make_executor(self, predict_chunk: Callable[[Any], Any] | None = None, executor_cls: Any = None) -> Any:
        """The policy's default executor around ``predict_chunk`` (default: ``self.predict_chunk``).

        ``executor_cls`` replaces the default class (e.g. a student's RecedingHorizon); it is called
        as ``executor_cls(predict_chunk, n_obs_steps=To, n_action_steps=Ta)``.
        """
        from coursekit.execution.receding import RecedingHorizon

        cls = executor_cls or RecedingHorizon
        return cls(predict_chunk or self.predict_chunk, n_obs_steps=self.config.n_obs_steps,
                   n_action_steps=self.config.n_action_steps)

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())
