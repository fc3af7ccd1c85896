"""Per-dimension normalisation whose statistics travel with the data and the checkpoint.

- :class:`MinMaxNormalizer` maps each dimension's [min, max] to [-1, 1]. Diffusion Policy needs
  it: its sampler clips samples to [-1, 1] (``clip_sample``), so a mean/std scaling would cut off
  large actions (a pitfall users report).
- :class:`MeanStdNormalizer` maps to zero mean, unit std, with std clipped below at 0.01 as in
  ACT's data loader.

Both work on numpy arrays and torch tensors alike (plain arithmetic against float32 arrays).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


def _as_stat(x: Any, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float32)
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise ValueError(f"normaliser statistic {name!r} must be a finite 1-d array, got {arr!r}")
    return arr


def _like(stat: np.ndarray, x: Any) -> Any:
    """The statistic as the same kind of array as x (torch tensor on x's device, or numpy)."""
    if hasattr(x, "new_tensor"):  # torch.Tensor, without importing torch here
        return x.new_tensor(stat)
    return stat


def _check_dim(x: Any, dim: int, who: str) -> None:
    if x.shape[-1] != dim:
        raise ValueError(f"{who}: last dimension {x.shape[-1]} does not match the {dim} dimensions it was fitted on (shape {tuple(x.shape)})")


@dataclass
class MinMaxNormalizer:
    """x -> 2 (x - min) / (max - min) - 1, per dimension; constant dimensions map to 0.

    Attributes:
        low: (D,) per-dimension minimum seen in the data.
        high: (D,) per-dimension maximum seen in the data.
    """

    low: np.ndarray
    high: np.ndarray
    kind = "minmax"

    def __post_init__(self) -> None:
        self.low, self.high = _as_stat(self.low, "low"), _as_stat(self.high, "high")
        if self.low.shape != self.high.shape or np.any(self.high < self.low):
            raise ValueError(f"need low <= high of one shape, got low={self.low}, high={self.high}")

    @classmethod
    def fit(cls, data: np.ndarray) -> MinMaxNormalizer:
        """Statistics of ``data`` (N, ..., D) over every axis but the last."""
        flat = np.asarray(data, dtype=np.float32).reshape(-1, np.shape(data)[-1])  # (N, D)
        return cls(flat.min(axis=0), flat.max(axis=0))

    @property
    def _scale(self) -> np.ndarray:
        span = self.high - self.low
        # A constant dimension has no range: map it to 0 rather than divide by zero.
        return np.where(span > 1e-6, 2.0 / np.maximum(span, 1e-6), 1.0).astype(np.float32)

    @property
    def _offset(self) -> np.ndarray:
        span = self.high - self.low
        mid = (self.high + self.low) / 2
        return np.where(span > 1e-6, mid, self.low).astype(np.float32)

    def normalize(self, x: Any) -> Any:
        """(..., D) raw -> (..., D) in [-1, 1] for data inside the fitted range."""
        _check_dim(x, len(self.low), "MinMaxNormalizer.normalize")
        return (x - _like(self._offset, x)) * _like(self._scale, x)

    def unnormalize(self, y: Any) -> Any:
        """(..., D) normalised -> (..., D) raw units."""
        _check_dim(y, len(self.low), "MinMaxNormalizer.unnormalize")
        return y / _like(self._scale, y) + _like(self._offset, y)

    def state_dict(self) -> dict[str, np.ndarray]:
        return {"low": self.low.copy(), "high": self.high.copy()}

    @classmethod
    def from_state_dict(cls, state: dict[str, Any]) -> MinMaxNormalizer:
        return cls(np.asarray(state["low"]), np.asarray(state["high"]))


@dataclass
class MeanStdNormalizer:
    """x -> (x - mean) / max(std, min_std), per dimension (ACT clips std at 0.01).

    Attributes:
        mean: (D,) per-dimension mean.
        std: (D,) per-dimension standard deviation, already clipped below at ``min_std``.
    """

    mean: np.ndarray
    std: np.ndarray
    kind = "meanstd"

    def __post_init__(self) -> None:
        self.mean, self.std = _as_stat(self.mean, "mean"), _as_stat(self.std, "std")
        if self.mean.shape != self.std.shape or np.any(self.std <= 0):
            raise ValueError(f"need mean/std of one shape with std > 0, got mean={self.mean}, std={self.std}")

    @classmethod
    def fit(cls, data: np.ndarray, min_std: float = 0.01) -> MeanStdNormalizer:
        flat = np.asarray(data, dtype=np.float64).reshape(-1, np.shape(data)[-1])  # (N, D)
        return cls(flat.mean(axis=0), np.maximum(flat.std(axis=0), min_std))

    def normalize(self, x: Any) -> Any:
        _check_dim(x, len(self.mean), "MeanStdNormalizer.normalize")
        return (x - _like(self.mean, x)) / _like(self.std, x)

    def unnormalize(self, y: Any) -> Any:
        _check_dim(y, len(self.mean), "MeanStdNormalizer.unnormalize")
        return y * _like(self.std, y) + _like(self.mean, y)

    def state_dict(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean.copy(), "std": self.std.copy()}

    @classmethod
    def from_state_dict(cls, state: dict[str, Any]) -> MeanStdNormalizer:
        return cls(np.asarray(state["mean"]), np.asarray(state["std"]))


def normalizer_from_state(kind: str, state: dict[str, Any]) -> MinMaxNormalizer | MeanStdNormalizer:
    """Rebuild a normaliser saved with ``state_dict`` (checkpoints store ``kind`` beside it)."""
    kinds = {"minmax": MinMaxNormalizer, "meanstd": MeanStdNormalizer}
    if kind not in kinds:
        raise ValueError(f"unknown normaliser kind {kind!r}; expected one of {sorted(kinds)}")
    return kinds[kind].from_state_dict(state)
