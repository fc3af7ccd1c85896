"""What every chunk policy shares: the contract the trainer, executors and checkpoints rely on.

A policy is a ``torch.nn.Module`` with

- ``policy_type`` (class attribute, e.g. "diffusion") and ``config_class`` (its dataclass);
- ``__init__(config, normalizers=None)``: the only constructor the checkpoint loader calls;
- ``normalizers``: name -> normaliser (``MinMaxNormalizer`` / ``MeanStdNormalizer``), fitted on the
  training data and saved in the checkpoint's config.json (so a policy is usable on its own);
- ``compute_loss(batch) -> dict`` with key "loss" (a scalar tensor) plus float diagnostics;
  ``batch`` is in RAW units, the policy normalises it;
- ``predict_chunk(obs_history, *, generator=None, **sampling) -> (B, Tp, Da)`` raw actions from
  a raw (B, To, ...) history (an unbatched (To, ...) history gives (Tp, Da)); ``generator``
  draws any noise, ``sampling`` holds the options named in ``sampling_options`` (diffusion:
  sampler, num_inference_steps), and nothing else;
- ``reset()`` between episodes; ``execution_spec()`` says how to execute its chunks and
  ``make_executor(predict_chunk, executor_cls)`` builds ``executor_cls.from_spec(...)``.

Each class also declares how it is trained, so one ``make_policy`` serves every policy type:
``make_config`` (config from the data's dimensions), ``make_batcher`` (its kind of training
sample) and ``recipes`` (named optimiser settings, :class:`coursekit.train.TrainConfig` fields).
Evaluation-time changes (``eval_overrides``, e.g. DDIM spacing or the ensembling decay) give a
validated COPY (``with_config``, via ``dataclasses.replace``); a loaded config is never edited.

The trainer owns the optimiser; the policy owns nothing but its weights and statistics.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from coursekit.data.normalize import MeanStdNormalizer, MinMaxNormalizer, normalizer_from_state
from coursekit.execution.spec import ExecutionSpec

Normalizer = MinMaxNormalizer | MeanStdNormalizer


def normalizers_to_json(normalizers: Mapping[str, Normalizer]) -> dict[str, Any]:
    """{name: normaliser} -> {name: {"kind": ..., "state": {stat: list}}} (JSON-ready)."""
    return {name: {"kind": n.kind, "state": {k: np.asarray(v).tolist() for k, v in n.state_dict().items()}}
            for name, n in normalizers.items()}


def normalizers_from_json(data: Mapping[str, Any]) -> dict[str, Normalizer]:
    """Inverse of :func:`normalizers_to_json`; a malformed entry -> ValueError naming it."""
    if not isinstance(data, Mapping):
        raise ValueError(f"normalizers must be a dict of name -> {{'kind', 'state'}}, got {type(data).__name__}")
    out = {}
    for name, entry in data.items():
        if not isinstance(entry, Mapping) or not isinstance(entry.get("state"), Mapping):
            raise ValueError(f"normaliser {name!r} must be a dict {{'kind': ..., 'state': {{stat: list}}}}, "
                             f"got {str(entry)[:80]!r}")
        try:
            out[name] = normalizer_from_state(entry.get("kind"), {k: np.asarray(v, dtype=np.float32)
                                                                  for k, v in entry["state"].items()})
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"normaliser {name!r} is malformed ({type(exc).__name__}: {exc}): {str(entry)[:80]!r}") from exc
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
    recipes: ClassVar[Mapping[str, Mapping[str, Any]]] = {"paper": {}}
    """Named training recipes: TrainConfig fields ("paper" = the paper's optimiser, "cpu" = a CPU budget's)."""
    eval_overrides: ClassVar[tuple[str, ...]] = ()
    """Config fields an evaluation may change (``with_config``): they touch no weight shape."""
    sampling_options: ClassVar[tuple[str, ...]] = ()
    """Keywords ``predict_chunk`` takes besides ``generator`` (deterministic policies: none)."""

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

    def execution_spec(self) -> ExecutionSpec:
        """To, Tp, Ta and the default executor kind (receding horizon unless overridden)."""
        c = self.config
        return ExecutionSpec(n_obs_steps=c.n_obs_steps, horizon=c.horizon, n_action_steps=c.n_action_steps)

    def make_executor(self, predict_chunk: Callable[..., Any] | None = None, executor_cls: Any = None,
                      **options: Any) -> Any:
        """An executor around ``predict_chunk`` (default: ``self.predict_chunk``).

        ``executor_cls`` replaces the default class (e.g. a student's RecedingHorizon or
        TemporalEnsemble, or a delayed executor of chapter 11); every executor class is built the
        same way: ``executor_cls.from_spec(predict_chunk, self.execution_spec(), **options)``
        (``options``: e.g. a delayed executor's ``delay``).
        """
        from coursekit.execution.ensembling import TemporalEnsemble
        from coursekit.execution.receding import RecedingHorizon

        spec = self.execution_spec()
        cls = executor_cls or (TemporalEnsemble if spec.temporal_ensembling else RecedingHorizon)
        return cls.from_spec(predict_chunk or self.predict_chunk, spec, **options)

    def check_sampling(self, sampling: Mapping[str, Any]) -> None:
        """Refuse sampling options this policy does not have (ValueError naming them)."""
        unknown = sorted(set(sampling) - set(self.sampling_options))
        if unknown:
            raise ValueError(f"a {self.policy_type!r} policy takes no sampling option(s) {unknown}; "
                             f"it has {list(self.sampling_options) or 'none'}")

    def describe_sampling(self, **sampling: Any) -> dict[str, Any]:
        """What ``predict_chunk(..., **sampling)`` runs, for evaluation reports (none for deterministic heads)."""
        self.check_sampling(sampling)
        return {}

    def with_config(self, **changes: Any) -> ChunkPolicy:
        """A copy sharing these weights and normalisers whose config has ``changes`` (validated).

        Only fields in ``eval_overrides`` may change (they touch no weight shape); the new config
        is ``dataclasses.replace(self.config, **changes)``, so its ``__post_init__`` checks it.
        """
        bad = sorted(set(changes) - set(self.eval_overrides))
        if bad:
            raise ValueError(f"{bad} are not evaluation settings of a {self.policy_type!r} policy; "
                             f"it has {list(self.eval_overrides)} (others are fixed by its training)")
        clone = copy.copy(self)  # shallow: the same modules, parameters and normalisers
        clone.config = dataclasses.replace(self.config, **changes)
        return clone

    # ---- training setup (used by coursekit.policies.factory.make_policy) ----------------
    @classmethod
    def make_config(cls, preset: str | None = None, **fields: Any) -> Any:
        """The config from the data's dimensions and the caller's fields (``preset``: a size preset, if any)."""
        if preset is not None:
            raise ValueError(f"{cls.__name__} has no config presets; got preset={preset!r}")
        return cls.config_class(**fields)

    def make_batcher(self, obs: Mapping[str, Any], action: Any, episode_ends: Any, *, batch_size: int,
                     seed: int = 0, device: Any = "cpu") -> Any:
        """The endless, seeded batch iterator this policy trains on (see coursekit.data.batches)."""
        raise NotImplementedError(f"{type(self).__name__} does not say how to batch its training data")

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())
