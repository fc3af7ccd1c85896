"""Training batches as tensors: one vectorised gather per batch, no per-sample Python.

The whole dataset lives as tensors (on the training device) and the windows of
:class:`coursekit.data.SequenceWindows` as one (W, Tp) index tensor, so a batch of B windows is

    idx    = windows[perm[i : i + B]]              (B, Tp)   rows into the flat arrays
    obs    = obs_array[idx[:, :To]]                (B, To, Do)  (per observation key)
    action = action_array[idx]                     (B, Tp, Da)

which is a handful of tensor ops whatever B is. On a 2-core CPU this matters: a per-sample
``Dataset.__getitem__`` + collate loop costs more than the network at the course's model size.

Batches are in RAW units (features, actions); the policy normalises them itself, because its
normalisers must travel with it into the checkpoint (see ``coursekit.policies.base``).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import torch

from coursekit.data.chunks import SequenceWindows
from coursekit.data.episodes import EpisodeDataset


class EpochSampler:
    """Endless batches of indices in [0, n): shuffled epochs without replacement, seeded.

    Each epoch is a fresh permutation from ``generator``; the last incomplete batch of an epoch
    is dropped (every batch has exactly ``batch_size`` rows, as the reference trainer does).
    If ``n < batch_size`` each batch is one permutation cut to ``n`` rows.
    """

    def __init__(self, n: int, batch_size: int, generator: torch.Generator):
        if n < 1:
            raise ValueError(f"EpochSampler needs at least one item, got n={n}")
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.n, self.batch_size, self.generator = int(n), int(batch_size), generator

    def __iter__(self) -> Iterator[torch.Tensor]:
        b = min(self.batch_size, self.n)
        while True:
            perm = torch.randperm(self.n, generator=self.generator)  # (n,)
            for start in range(0, self.n - b + 1, b):
                yield perm[start : start + b]  # (B,)


def _as_tensor(x: Any, name: str, device: torch.device) -> torch.Tensor:
    """A float32 tensor (uint8 images stay uint8), checked for NaN/inf once, up front."""
    t = torch.as_tensor(np.asarray(x))
    if t.dtype != torch.uint8:
        t = t.to(torch.float32)
        finite = torch.isfinite(t).reshape(len(t), -1).all(dim=1)  # (N,)
        if not bool(finite.all()):
            bad = int(torch.nonzero(~finite)[0])
            raise ValueError(f"training array {name!r} contains NaN or inf (first at row {bad}: {t[bad].tolist()})")
    return t.to(device)


class WindowBatcher:
    """Diffusion Policy training batches (dicts of tensors) from flat per-step arrays.

    Args:
        obs: observation key -> (N, ...) array (e.g. "obs" (N, Do) features, or "image"
            (N, 3, H, W) uint8 plus "agent_pos" (N, 2)).
        action: (N, Da) actions.
        episode_ends: (E,) exclusive episode ends (``EpisodeDataset.episode_ends``).
        horizon, n_obs_steps, n_action_steps: Tp, To, Ta of the windows (edge padding as in
            :class:`SequenceWindows`).
        batch_size: B.
        seed: seeds the shuffling generator (deterministic batches).
        device: where the arrays and batches live.

    Iterating yields ``{key: (B, To, ...) for each obs key, "action": (B, Tp, Da)}`` forever.
    """

    def __init__(self, obs: Mapping[str, Any], action: Any, episode_ends: np.ndarray, *, horizon: int = 16,
                 n_obs_steps: int = 2, n_action_steps: int = 8, batch_size: int = 256, seed: int = 0,
                 device: torch.device | str = "cpu"):
        if not obs:
            raise ValueError("WindowBatcher needs at least one observation array")
        if "action" in obs:
            raise ValueError("'action' is reserved for the action array; rename that observation key")
        device = torch.device(device)
        self.windows = SequenceWindows.build(episode_ends, horizon=horizon, n_obs_steps=n_obs_steps,
                                             n_action_steps=n_action_steps)
        self.action = _as_tensor(action, "action", device)
        self.obs = {k: _as_tensor(v, k, device) for k, v in obs.items()}
        n = int(np.asarray(episode_ends)[-1])
        for k, v in [("action", self.action), *self.obs.items()]:
            if len(v) != n:
                raise ValueError(f"array {k!r} has {len(v)} rows but episode_ends says {n} steps")
        self.index = torch.as_tensor(self.windows.indices, device=device)  # (W, Tp)
        self.n_obs_steps, self.batch_size = int(n_obs_steps), int(batch_size)
        self.generator = torch.Generator().manual_seed(int(seed))
        self.sampler = EpochSampler(len(self.windows), batch_size, self.generator)

    def __len__(self) -> int:
        """Number of windows (training samples per epoch)."""
        return len(self.windows)

    def batch(self, which: torch.Tensor) -> dict[str, torch.Tensor]:
        """The windows ``which`` (B,) as a batch dict (see class docstring)."""
        idx = self.index[which.to(self.index.device)]  # (B, Tp)
        out = {k: v[idx[:, : self.n_obs_steps]] for k, v in self.obs.items()}  # (B, To, ...)
        out["action"] = self.action[idx]  # (B, Tp, Da)
        return out

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        for which in self.sampler:
            yield self.batch(which)


def pusht_training_arrays(dataset: EpisodeDataset, features: str = "pusht_state") -> tuple[dict[str, np.ndarray], np.ndarray]:
    """PushT demonstrations -> ({"obs": (N, Do) features}, action (N, Da)) for :class:`WindowBatcher`.

    ``features`` names a function of :mod:`coursekit.data.features` applied to the "state" array.
    """
    from coursekit.data.features import get_features

    for key in ("state", "action"):
        if key not in dataset.arrays:
            raise ValueError(f"dataset lacks the {key!r} array (has {sorted(dataset.arrays)}); "
                             "expected PushT demonstrations from `coursekit collect pusht`")
    return {"obs": get_features(features)(dataset["state"])}, np.asarray(dataset["action"], dtype=np.float32)
