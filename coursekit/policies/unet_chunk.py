"""The part Diffusion Policy and its regression baseline share: observations in, a 1-D U-Net body.

Both policies see the same inputs, normalised the same way, and use the same conditional U-Net
(``coursekit.nn.unet1d.ConditionalUnet1D``), so that comparing them isolates one thing: whether
the chunk is sampled by denoising (multimodal) or regressed directly (the conditional mean).

Observation conditioning (Chi et al. 2023, Sec. 3.2 "global conditioning" via FiLM)::

    low_dim:  batch["obs"]        (B, To, Do) raw features  -> min-max to [-1, 1] -> flatten (B, To*Do)
    image:    batch["image"]      (B, To, C, H, W) uint8     -> [-1, 1] -> VisionEncoder (B*To, F)
              batch["agent_pos"]  (B, To, Dp) raw            -> min-max to [-1, 1]
                                  concat per step, flatten  -> (B, To*(F + Dp))

Actions are min-max normalised to [-1, 1] too (required by the sampler's clip_sample).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from coursekit.data.batches import WindowBatcher
from coursekit.data.normalize import MinMaxNormalizer
from coursekit.execution.spec import check_horizons
from coursekit.nn.unet1d import ConditionalUnet1D, UNet1DConfig
from coursekit.nn.vision import VisionEncoder, VisionEncoderConfig
from coursekit.policies.base import ChunkPolicy, Normalizer, as_float_tensor

OBS_TYPES = ("low_dim", "image")


@dataclass
class UNetChunkConfig:
    """Inputs, horizons and U-Net size shared by Diffusion Policy and the regression baseline."""

    obs_type: str = "low_dim"
    """'low_dim' (a feature vector per step) or 'image' (one camera + agent position)."""
    features: str = "pusht_state"
    """How observations become policy inputs: a key of coursekit.data.features.FEATURES (any task)."""
    obs_dim: int = 6
    """Do: low-dim features per step (image: dimension of agent_pos, e.g. 2)."""
    action_dim: int = 2
    """Da: dimension of one action (PushT: target x, y; ALOHA: 14 joint targets)."""
    n_obs_steps: int = 2
    """To: observation steps the policy conditions on."""
    horizon: int = 16
    """Tp: actions predicted per chunk."""
    n_action_steps: int = 8
    """Ta: actions executed from each chunk before re-planning."""
    unet: UNet1DConfig = field(default_factory=UNet1DConfig)
    """Size of the conditional 1-D U-Net (preset 'cpu' by default; 'paper_lowdim' for the paper's)."""
    vision: VisionEncoderConfig | None = None
    """Image encoder (obs_type 'image' only; None there means the 'cpu' preset)."""

    def __post_init__(self) -> None:
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {self.obs_type!r}")
        for name in ("obs_dim", "action_dim"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{name} must be a positive int, got {v!r}")
        check_horizons(self.n_obs_steps, self.horizon, self.n_action_steps)
        levels = len(self.unet.down_dims)
        if self.horizon % (2 ** (levels - 1)):
            raise ValueError(f"horizon {self.horizon} must be divisible by 2**(len(down_dims)-1) = {2 ** (levels - 1)} "
                             f"(down_dims={self.unet.down_dims})")
        if self.obs_type == "image" and self.vision is None:
            self.vision = VisionEncoderConfig()
        if self.obs_type == "low_dim" and self.vision is not None:
            raise ValueError(f"vision config given for obs_type 'low_dim': {self.vision!r}")


class UNetChunkPolicy(ChunkPolicy):
    """Normalisation + observation encoding + the U-Net; subclasses define the loss and the prediction."""

    config: UNetChunkConfig
    # Diffusion Policy's recipe (Chi et al. 2023, App. A; TrainConfig's defaults: AdamW lr 1e-4,
    # batch 256, 500 warm-up steps, cosine, EMA) and "cpu", a deliberate departure for a
    # ~20-minute CPU budget, where the paper's recipe (tuned for hours) has barely left its
    # warm-up: in 4.5-minute runs on one core the held-out epsilon loss was 0.072 (cpu) vs 0.164
    # (paper) for the 64/128/256 U-Net, and 0.065 vs 0.132 for 32/64/128 (batch 128 gives twice
    # the optimiser steps at about the same samples/s).
    recipes = {"paper": {"batch_size": 256}, "cpu": {"lr": 5e-4, "batch_size": 128}}
    eval_overrides = ("n_action_steps",)

    def __init__(self, config: UNetChunkConfig, normalizers: Mapping[str, Normalizer] | None = None):
        super().__init__(config, normalizers)
        c = config
        if c.obs_type == "image":
            self.vision_encoder: VisionEncoder | None = VisionEncoder(c.vision)
            per_step = c.vision.feature_dim + c.obs_dim
        else:
            self.vision_encoder = None
            per_step = c.obs_dim
        self.cond_dim = c.n_obs_steps * per_step
        self.unet = ConditionalUnet1D(c.action_dim, self.cond_dim, c.unet)

    # ---- normalisation -----------------------------------------------------------------
    @property
    def obs_keys(self) -> tuple[str, ...]:
        """Keys of the observation dict the policy reads."""
        return ("image", "agent_pos") if self.config.obs_type == "image" else ("obs",)

    def normalizer_dims(self) -> dict[str, int]:
        key = "agent_pos" if self.config.obs_type == "image" else "obs"
        return {key: self.config.obs_dim, "action": self.config.action_dim}

    def fit_normalizers(self, obs: Mapping[str, Any], action: Any) -> None:
        """Fit min-max normalisers on training arrays: obs {"obs": (N, Do)} or {"agent_pos": (N, Dp), ...}, action (N, Da)."""
        key = "agent_pos" if self.config.obs_type == "image" else "obs"
        if key not in obs:
            raise ValueError(f"fit_normalizers needs obs[{key!r}], got keys {sorted(obs)}")
        self.set_normalizers({key: MinMaxNormalizer.fit(np.asarray(obs[key])),
                              "action": MinMaxNormalizer.fit(np.asarray(action))})

    def make_batcher(self, obs: Mapping[str, Any], action: Any, episode_ends: Any, *, batch_size: int,
                     seed: int = 0, device: Any = "cpu") -> WindowBatcher:
        """Windows of To observations and Tp actions, ``{obs keys: (B, To, ...), "action": (B, Tp, Da)}``."""
        c = self.config
        return WindowBatcher(obs, action, episode_ends, horizon=c.horizon, n_obs_steps=c.n_obs_steps,
                             n_action_steps=c.n_action_steps, batch_size=batch_size, seed=seed, device=device)

    # ---- observations ------------------------------------------------------------------
    def _obs_dict(self, obs_history: Any) -> tuple[dict[str, torch.Tensor], bool]:
        """Raw history (B, To, ...) as a checked dict of tensors on the policy's device; also 'was unbatched'."""
        c = self.config
        if not isinstance(obs_history, Mapping):
            if c.obs_type == "image":
                raise ValueError("an image policy needs a dict {'image': (B, To, C, H, W), 'agent_pos': (B, To, Dp)}, "
                                 f"got {type(obs_history).__name__}")
            obs_history = {"obs": obs_history}
        missing = [k for k in self.obs_keys if k not in obs_history]
        if missing:
            raise ValueError(f"observation history lacks {missing}; expected keys {list(self.obs_keys)}")
        device = self.device
        out = {k: as_float_tensor(obs_history[k], f"observation {k!r}", device) for k in self.obs_keys}
        low_key = "agent_pos" if c.obs_type == "image" else "obs"
        unbatched = out[low_key].ndim == 2
        if unbatched:
            out = {k: v.unsqueeze(0) for k, v in out.items()}  # (1, To, ...)
        low = out[low_key]
        if low.ndim != 3 or low.shape[1:] != (c.n_obs_steps, c.obs_dim):
            raise ValueError(f"observation {low_key!r} must have shape (B, To={c.n_obs_steps}, Do={c.obs_dim}) "
                             f"or (To, Do), got {tuple(obs_history[low_key].shape)}")
        if c.obs_type == "image":
            img = out["image"]
            want = (c.n_obs_steps, c.vision.in_channels, *c.vision.image_size)
            if img.ndim != 5 or tuple(img.shape[1:]) != want or img.shape[0] != low.shape[0]:
                raise ValueError(f"observation 'image' must have shape (B, {', '.join(map(str, want))}) "
                                 f"(uint8 0..255 or float in [0, 1]), got {tuple(img.shape)}")
        return out, unbatched

    def encode_obs(self, obs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """Checked raw observation tensors (B, To, ...) -> global condition (B, cond_dim)."""
        c = self.config
        if c.obs_type == "low_dim":
            x = self.normalizers["obs"].normalize(obs["obs"])  # (B, To, Do)
            return x.reshape(x.shape[0], -1)  # (B, To*Do)
        img = obs["image"]
        b, to = img.shape[:2]
        # uint8 0..255 or float 0..1 -> [-1, 1] (images are min-max scaled too, Sec. 5 of the paper's code)
        img = img.float() / 255.0 if img.dtype == torch.uint8 else img.float()
        feats = self.vision_encoder(img.reshape(b * to, *img.shape[2:]) * 2.0 - 1.0)  # (B*To, F)
        feats = feats.reshape(b, to, -1)  # (B, To, F)
        pos = self.normalizers["agent_pos"].normalize(obs["agent_pos"])  # (B, To, Dp)
        return torch.cat([feats, pos], dim=-1).reshape(b, -1)  # (B, To*(F+Dp))

    def _batch_parts(self, batch: Mapping[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        """A raw training batch -> (global condition (B, cond_dim), normalised actions (B, Tp, Da))."""
        self._require_normalizers()
        c = self.config
        if "action" not in batch:
            raise ValueError(f"training batch lacks 'action'; got keys {sorted(batch)}")
        obs, unbatched = self._obs_dict({k: batch[k] for k in self.obs_keys if k in batch})
        action = as_float_tensor(batch["action"], "batch 'action'", self.device)
        if unbatched or action.shape != (obs[self.obs_keys[-1]].shape[0], c.horizon, c.action_dim):
            raise ValueError(f"batch 'action' must have shape (B, Tp={c.horizon}, Da={c.action_dim}) matching the "
                             f"observations' B, got {tuple(action.shape)}")
        return self.encode_obs(obs), self.normalizers["action"].normalize(action)

    def _sample_chunk(self, obs_history: Any, draw: Any, return_trajectory: bool = False) -> Any:
        """The prediction shared by every generative head on this backbone: check and encode the
        raw history, call ``draw(cond (B, cond_dim), shape (B, Tp, Da))`` in eval mode (centre crop
        for images; no dropout), restore the training flag, and return raw units as
        :meth:`predict_chunk` promises. ``draw`` returns the normalised chunk (B, Tp, Da), or
        (chunk, path (n+1, B, Tp, Da)) with ``return_trajectory``; the path comes back in raw units."""
        self._require_normalizers()
        c = self.config
        obs, unbatched = self._obs_dict(obs_history)
        was_training = self.training
        self.eval()
        try:
            cond = self.encode_obs(obs)  # (B, cond_dim)
            out = draw(cond, (cond.shape[0], c.horizon, c.action_dim))
        finally:
            self.train(was_training)
        if return_trajectory:
            chunk_n, traj_n = out
            traj = self.normalizers["action"].unnormalize(traj_n)  # (n+1, B, Tp, Da)
            return self._finish(chunk_n, obs_history, unbatched), traj
        return self._finish(out, obs_history, unbatched)

    def _finish(self, chunk_n: torch.Tensor, like: Any, unbatched: bool) -> Any:
        """Normalised chunk (B, Tp, Da) -> raw units, unbatched if the input was, numpy if the input was."""
        chunk = self.normalizers["action"].unnormalize(chunk_n)  # (B, Tp, Da)
        if unbatched:
            chunk = chunk[0]  # (Tp, Da)
        first = next(iter(like.values())) if isinstance(like, Mapping) else like
        return chunk.detach().cpu().numpy() if isinstance(first, np.ndarray) else chunk
