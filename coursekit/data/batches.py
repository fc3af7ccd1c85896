"""Training batches as tensors: one vectorised gather per batch, no per-sample Python.

Two batchers, one per kind of training sample (a policy class declares which it uses):

- :class:`WindowBatcher` (Diffusion Policy and the U-Net policies): windows of To observations
  and Tp actions, edge-padded (:class:`coursekit.data.SequenceWindows`);
- :class:`ChunkBatcher` (ACT, Zhao et al. 2023, Sec. IV): the observation at t and the next k
  actions, zero-padded past the episode's end with an ``action_is_pad`` mask
  (:class:`coursekit.data.ActionChunks`). Departure: the original draws a random episode, then
  a random t in it; we draw t uniformly over all steps (shuffled epochs). With equal episode
  lengths (the scripted ALOHA data: 400 steps each) the two are the same distribution.

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

from coursekit.data.chunks import ActionChunks, SequenceWindows


class EpochSampler:
    """Endless batches of indices in [0, n): shuffled epochs without replacement, seeded.

    Each epoch is a fresh permutation from ``generator``; the last incomplete batch of an epoch
    is dropped (every batch has exactly ``batch_size`` rows, as the reference trainer does).
    If ``n < batch_size`` each batch is one permutation cut to ``n`` rows.

    The position in the current epoch is explicit state (``perm``, ``pos``), so a training run can
    save it with :meth:`state_dict` and continue with exactly the batches it would have drawn.
    """

    def __init__(self, n: int, batch_size: int, generator: torch.Generator):
        if n < 1:
            raise ValueError(f"EpochSampler needs at least one item, got n={n}")
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.n, self.batch_size, self.generator = int(n), int(batch_size), generator
        self.perm: torch.Tensor | None = None  # (n,) the current epoch's order
        self.pos = 0  # rows of perm already handed out

    def next_indices(self) -> torch.Tensor:
        """The next batch of indices (B,), B = min(batch_size, n); a new epoch when this one is used up."""
        b = min(self.batch_size, self.n)
        if self.perm is None or self.pos + b > self.n:
            self.perm = torch.randperm(self.n, generator=self.generator)  # (n,)
            self.pos = 0
        out = self.perm[self.pos : self.pos + b]  # (B,)
        self.pos += b
        return out

    def __iter__(self) -> Iterator[torch.Tensor]:
        while True:
            yield self.next_indices()

    def state_dict(self) -> dict[str, Any]:
        """Everything that decides the batches still to come: the generator, the epoch order and position."""
        return {"n": self.n, "batch_size": self.batch_size, "generator": self.generator.get_state(),
                "perm": None if self.perm is None else self.perm.clone(), "pos": self.pos}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Continue from ``state`` (from :meth:`state_dict` of a sampler over the same n and batch size)."""
        if (state.get("n"), state.get("batch_size")) != (self.n, self.batch_size):
            raise ValueError(f"sampler state is for n={state.get('n')}, batch_size={state.get('batch_size')}; "
                             f"this sampler has n={self.n}, batch_size={self.batch_size}")
        self.generator.set_state(state["generator"])
        self.perm = None if state["perm"] is None else state["perm"].clone()
        self.pos = int(state["pos"])


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

    def state_dict(self) -> dict[str, Any]:
        """The shuffling state (see :meth:`EpochSampler.state_dict`): save it to resume a run exactly."""
        return self.sampler.state_dict()

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Continue drawing batches from ``state`` (a :meth:`state_dict` of a batcher over the same data)."""
        self.sampler.load_state_dict(state)


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

    def state_dict(self) -> dict[str, Any]:
        """The shuffling state (see :meth:`EpochSampler.state_dict`): save it to resume a run exactly."""
        return self.sampler.state_dict()

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Continue drawing batches from ``state`` (a :meth:`state_dict` of a batcher over the same data)."""
        self.sampler.load_state_dict(state)
