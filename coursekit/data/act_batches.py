"""ACT training batches and observation features: what one ACT sample sees, as tensors.

One sample (Zhao et al. 2023, Sec. IV and the original ``EpisodicDataset``): the observation at
a time t and the next k actions, zero-padded past the episode's end with an ``is_pad`` mask::

    obs      o_t                         (Do,)
    action   a_t, a_t+1, ..., a_t+k-1    (k, Da)   steps past the episode end: 0, is_pad = True

The windows are :class:`coursekit.data.ActionChunks` (one per step); a batch is one tensor gather,
as in :class:`coursekit.data.batches.WindowBatcher`. Departure: the original draws a random
episode, then a random t in it; we draw t uniformly over all steps (shuffled epochs). With equal
episode lengths (the scripted ALOHA data: 400 steps each) the two are the same distribution.

Observation features (``ACT_FEATURES``; a policy stores the name in ``ACTConfig.features``)::

    aloha_state  [qpos (14), env_state (7 cube | 14 peg + socket)]   (21 or 28)
    aloha_qpos   qpos (14): proprioception only (cannot see where the object is)
    pusht_state  [agent_x, agent_y, block_x, block_y, sin angle, cos angle]   (6)
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import torch

from coursekit.data.batches import EpochSampler
from coursekit.data.chunks import ActionChunks
from coursekit.data.episodes import EpisodeDataset


def _aloha_state(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    return np.concatenate([np.asarray(obs["qpos"]), np.asarray(obs["env_state"])], axis=-1).astype(np.float32)


def _aloha_qpos(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    return np.asarray(obs["qpos"], dtype=np.float32)


def _pusht_state(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    from coursekit.data.features import pusht_state_features

    return pusht_state_features(np.asarray(obs["state"]))


ACT_FEATURES: dict[str, tuple[tuple[str, ...], Callable[[Mapping[str, np.ndarray]], np.ndarray]]] = {
    "aloha_state": (("qpos", "env_state"), _aloha_state),
    "aloha_qpos": (("qpos",), _aloha_qpos),
    "pusht_state": (("state",), _pusht_state),
}
"""Feature name -> (the arrays it reads, function {name: (..., d)} -> (..., Do) float32)."""


def act_features(name: str, arrays: Mapping[str, np.ndarray]) -> np.ndarray:
    """Features ``name`` of per-step arrays (dataset arrays (N, ...) or stacked env observations (B, ...))."""
    if name not in ACT_FEATURES:
        raise ValueError(f"unknown ACT features {name!r}; expected one of {sorted(ACT_FEATURES)}")
    keys, fn = ACT_FEATURES[name]
    missing = [k for k in keys if k not in arrays]
    if missing:
        raise ValueError(f"features {name!r} need arrays {list(keys)}; missing {missing} (have {sorted(arrays)})")
    return fn(arrays)


def env_obs_features(name: str, observations: Sequence[Any]) -> np.ndarray:
    """A list of B raw env observations (dicts, or PushT state vectors) -> (B, Do) features."""
    first = observations[0]
    if isinstance(first, Mapping):
        stacked = {k: np.stack([np.asarray(o[k]) for o in observations]) for k in first}  # (B, ...)
    else:
        stacked = {"state": np.stack([np.asarray(o) for o in observations])}  # (B, 5)
    return act_features(name, stacked)


def act_training_arrays(dataset: EpisodeDataset, features: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Demonstrations -> ({"obs": (N, Do)}, action (N, Da)) for :class:`ChunkBatcher` and ``fit_normalizers``."""
    if "action" not in dataset.arrays:
        raise ValueError(f"dataset lacks the 'action' array (has {sorted(dataset.arrays)})")
    return {"obs": act_features(features, dataset.arrays)}, np.asarray(dataset["action"], dtype=np.float32)


class ChunkBatcher:
    """Endless ACT training batches ``{"obs": (B, Do), "action": (B, k, Da), "action_is_pad": (B, k)}``.

    Args:
        obs: {"obs": (N, Do)} raw features, optionally "image": (N, C, H, W) uint8.
        action: (N, Da) raw actions.
        episode_ends: (E,) exclusive episode ends.
        chunk_size: k.
        batch_size: B.
        seed: seeds the shuffling (deterministic batches).
        device: where the arrays and batches live.
    """

    def __init__(self, obs: Mapping[str, Any], action: Any, episode_ends: np.ndarray, *, chunk_size: int = 100,
                 batch_size: int = 8, seed: int = 0, device: torch.device | str = "cpu") -> None:
        if "obs" not in obs:
            raise ValueError(f"ChunkBatcher needs obs['obs'] (N, Do), got keys {sorted(obs)}")
        device = torch.device(device)
        self.chunks = ActionChunks.build(episode_ends, chunk_size)
        n = len(self.chunks)
        self.obs = {}
        for k, v in obs.items():
            t = torch.as_tensor(np.asarray(v))
            if t.dtype != torch.uint8:
                t = t.float()
                if not bool(torch.isfinite(t).all()):
                    raise ValueError(f"training array {k!r} contains NaN or inf")
            if len(t) != n:
                raise ValueError(f"array {k!r} has {len(t)} rows but episode_ends says {n} steps")
            self.obs[k] = t.to(device)
        self.action = torch.as_tensor(np.asarray(action), dtype=torch.float32, device=device)  # (N, Da)
        if len(self.action) != n or not bool(torch.isfinite(self.action).all()):
            raise ValueError(f"action must be finite with {n} rows, got shape {tuple(self.action.shape)}")
        self.start = torch.as_tensor(self.chunks.start, device=device)  # (W,)
        self.index = torch.as_tensor(self.chunks.indices, device=device)  # (W, k)
        self.is_pad = torch.as_tensor(self.chunks.is_pad, device=device)  # (W, k)
        self.batch_size = int(batch_size)
        self.generator = torch.Generator().manual_seed(int(seed))
        self.sampler = EpochSampler(n, self.batch_size, self.generator)

    def __len__(self) -> int:
        """Number of windows (one per step)."""
        return len(self.chunks)

    def batch(self, which: torch.Tensor) -> dict[str, torch.Tensor]:
        """The windows ``which`` (B,) as a batch dict (see class docstring); padded actions are 0."""
        which = which.to(self.start.device)
        pad = self.is_pad[which]  # (B, k)
        out = {k: v[self.start[which]] for k, v in self.obs.items()}  # (B, Do) / (B, C, H, W)
        out["action"] = self.action[self.index[which]].masked_fill(pad[..., None], 0.0)  # (B, k, Da)
        out["action_is_pad"] = pad
        return out

    def __iter__(self) -> Iterator[dict[str, torch.Tensor]]:
        for which in self.sampler:
            yield self.batch(which)
