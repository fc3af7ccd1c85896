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

The generative heads (diffusion, flow) share more: :class:`IterativeUNetPolicy`, a chunk sampled
from noise in steps, which real-time chunking can steer step by step (``predict_inpainted``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import torch

from coursekit.data.batches import WindowBatcher
from coursekit.data.normalize import MinMaxNormalizer
from coursekit.data.frames import check_values
from coursekit.execution.rtc import MAX_GUIDANCE, PREFIX_MODES, GuidedHead, sample_guided
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
            want = (c.n_obs_steps, c.vision.in_channels, *c.vision.input_size)
            if img.ndim != 5 or tuple(img.shape[1:]) != want or img.shape[0] != low.shape[0]:
                hint = " (channels last? frames go channels first)" if img.shape[-1] == c.vision.in_channels else ""
                raise ValueError(f"observation 'image' must have shape (B, {', '.join(map(str, want))}) "
                                 f"(uint8 0..255 or float in [0, 1]), got {tuple(img.shape)}{hint}")
            check_values(torch.as_tensor(obs_history["image"]), "observation 'image'")  # 0..255 floats would saturate
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


class IterativeUNetPolicy(UNetChunkPolicy):
    """A chunk sampled from noise in steps (diffusion: denoising; flow: integration) on this backbone.

    Each subclass draws its starting noise with :meth:`initial_noise`, ends with
    :meth:`finish_sample`, and shows its own sampler one step at a time through
    :meth:`guided_head`; :meth:`predict_inpainted` runs that head under real-time chunking's
    guidance (:mod:`coursekit.execution.rtc`). With all-zero weights it is ``predict_chunk``
    exactly: the same noise from the same generator, the same steps.
    """

    guided_sampling_options: ClassVar[tuple[str, ...]] = ("sampler", "num_inference_steps")
    """The sampling options ``predict_inpainted`` takes (a subset of ``sampling_options``)."""

    def initial_noise(self, shape: tuple[int, ...], generator: torch.Generator | None, device: Any) -> torch.Tensor:
        """The chunk at the noise end, N(0, I) of ``shape`` (B, Tp, Da), drawn on the generator's device."""
        gen_device = generator.device if generator is not None else device
        return torch.randn(shape, generator=generator, device=gen_device).to(device)

    def finish_sample(self, chunk_n: torch.Tensor) -> torch.Tensor:
        """The last touch on a sampled normalised chunk (B, Tp, Da): none unless a head says otherwise."""
        return chunk_n

    def guided_head(self, cond: torch.Tensor, generator: torch.Generator | None = None,
                    **sampling: Any) -> GuidedHead:
        """This policy's sampler for condition ``cond`` (B, cond_dim), seen one step at a time."""
        raise NotImplementedError(f"{type(self).__name__} does not show its sampler step by step")

    def predict_inpainted(self, obs_history: Any, target: Any, weights: Any, *, frozen: int = 0,
                          generator: torch.Generator | None = None, max_guidance: float = MAX_GUIDANCE,
                          offset: int | None = None, prefix: str = "guide", **sampling: Any) -> Any:
        """A chunk (B, Tp, Da) whose steps ``offset + j`` are guided toward ``target[:, j]`` (RTC).

        Args:
            obs_history: raw history (B, To, ...) as for ``predict_chunk``.
            target: Y, raw actions (B, n, Da) for chunk indices offset .. offset + n - 1.
            weights: W (n,), >= 0 (:func:`coursekit.execution.rtc.rtc_weights`).
            frozen: the first ``frozen`` target actions are copied verbatim into the result.
            generator: draws the starting noise (and DDPM's step noise), as ``predict_chunk`` does.
            max_guidance: beta, the clip of the guidance weight (RTC: 5).
            offset: chunk index of target[:, 0] (default To - 1: the action for "now").
            prefix: "guide" or "replace" (:data:`coursekit.execution.rtc.PREFIX_MODES`).
            sampling: the options in ``guided_sampling_options``.
        Returns raw actions, numpy if the history was numpy.
        """
        if prefix not in PREFIX_MODES:
            raise ValueError(f"prefix must be one of {PREFIX_MODES}, got {prefix!r}")
        unknown = sorted(set(sampling) - set(self.guided_sampling_options))
        if unknown:
            raise ValueError(f"predict_inpainted takes the sampling options {' and '.join(self.guided_sampling_options)}, "
                             f"got {unknown}")
        c = self.config
        offset = c.n_obs_steps - 1 if offset is None else int(offset)
        w = np.asarray(weights, dtype=np.float64)
        y = np.asarray(target.detach().cpu() if hasattr(target, "detach") else target, dtype=np.float64)
        if y.ndim != 3 or w.shape != (y.shape[1],) or offset + y.shape[1] > c.horizon or y.shape[2] != c.action_dim:
            raise ValueError(f"target must be (B, n, Da={c.action_dim}) with weights (n,) and offset + n <= Tp={c.horizon}; "
                             f"got target {y.shape}, weights {w.shape}, offset {offset}")
        if not (np.all(np.isfinite(w)) and np.all(w >= 0)) or not 0 <= frozen <= y.shape[1]:
            raise ValueError(f"weights must be finite and >= 0 and 0 <= frozen <= n={y.shape[1]}; got {w}, frozen={frozen}")

        def draw(cond: torch.Tensor, shape: tuple[int, int, int]) -> torch.Tensor:
            cond, dev = cond.detach(), cond.device  # guidance differentiates the iterate, not the observation
            if y.shape[0] != shape[0]:
                raise ValueError(f"target has batch {y.shape[0]}, the observations {shape[0]}")
            full_y = torch.zeros(shape, device=dev)  # (B, Tp, Da), normalised
            full_y[:, offset:offset + y.shape[1]] = self.normalizers["action"].normalize(
                torch.as_tensor(y, dtype=torch.float32, device=dev))
            full_w = torch.zeros(c.horizon, device=dev)  # (Tp,)
            full_w[offset:offset + len(w)] = torch.as_tensor(w, dtype=torch.float32, device=dev)
            x = self.initial_noise(shape, generator, dev)  # (B, Tp, Da), as predict_chunk draws it
            head = self.guided_head(cond, generator, **sampling)
            replace = None
            if prefix == "replace" and frozen:
                replace = torch.zeros(c.horizon, dtype=torch.bool, device=dev)
                replace[offset:offset + frozen] = True
            return self.finish_sample(sample_guided(head, x, full_y, full_w, max_guidance, replace=replace))

        chunk = self._sample_chunk(obs_history, draw)
        if frozen:  # the committed actions, exactly (chunk (B, Tp, Da), or (Tp, Da) for an unbatched history)
            src = y[:, :frozen] if chunk.ndim == 3 else y[0, :frozen]  # (B, frozen, Da) or (frozen, Da)
            chunk[..., offset:offset + frozen, :] = src if isinstance(chunk, np.ndarray) else chunk.new_tensor(src)
        return chunk
