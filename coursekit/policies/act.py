"""ACT: Action Chunking with Transformers (Zhao et al., RSS 2023), a CVAE over action chunks.

Training (Sec. IV-B and IV-C, Fig. 4)::

    CVAE encoder (training only)                        decoder side (training and deployment)
    tokens [CLS, proj(o_t), proj(a_t) .. proj(a_t+k-1)]    encoder tokens [proj(z), proj(o_t), image tokens]
      + 1-D sine positions, padded actions masked            + learned positions (2-D sine for images)
    -> transformer encoder -> CLS -> Linear                  -> transformer encoder
    -> (mu, log sigma^2) -> z = mu + sigma * eps             k learned queries -> transformer decoder
                                                             -> Linear -> k actions (B, k, Da)

    loss = L1(actions, predicted) over non-padded steps + beta * KL(q(z | a, o) || N(0, I))

Deployment: z = 0 (the prior mean), so a chunk is a deterministic function of the observation.

Departures from the original code, on purpose:

- Observations: ``o_t`` is a low-dim feature vector of size Do (ALOHA: qpos (14) + the object
  poses the env exposes), projected to ONE token; the paper's token is qpos alone and the scene
  is seen through images (available here with ``obs_type="image"``: features 'aloha_image', the
  arm pair's "top" camera rendered from the stored states beside qpos, at 96x128 with the "arm_pair"
  preset where the paper's simulated tasks use 480x640).
- The FULL decoder stack is used (the original keeps only the first decoder layer's output by
  a slip; see :mod:`coursekit.nn.act_transformer`).
- The L1 term is the mean over NON-padded entries; the original multiplies by the mask and then
  averages over all entries, so chunks near an episode's end count less than they should.
- The image backbone is a GroupNorm ResNet-18-style trunk trained from scratch (no ImageNet
  download is possible here); the paper fine-tunes a pretrained ResNet-18 with frozen BatchNorm.

Normalisation (per-dimension mean/std, std clipped at 0.01, as ACT's data loader) lives in the
policy: ``compute_loss`` and ``predict_chunk`` take RAW units, and the statistics travel in the
checkpoint (normalisers "obs" and "action").
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from coursekit.data.batches import ChunkBatcher
from coursekit.data.normalize import MeanStdNormalizer
from coursekit.data.frames import check_values
from coursekit.execution.spec import ExecutionSpec
from coursekit.nn.act_transformer import ACTTransformer, TransformerEncoder
from coursekit.nn.kl import gaussian_kl
from coursekit.nn.positional import sinusoidal_1d, sinusoidal_2d
from coursekit.nn.vision import VisionEncoder, VisionEncoderConfig
from coursekit.policies.base import ChunkPolicy, Normalizer, as_float_tensor

OBS_TYPES = ("low_dim", "image")


@dataclass
class ACTConfig:
    """ACT's inputs, sizes, loss weight and executor. Defaults: the CPU size; ``ACTConfig.paper()``: Table VI.

    Why this CPU size: a train step costs about (CVAE encoder layers + ~1.3 x decoder layers) x
    (k + 2) tokens x D^2 (the decoder-side encoder sees only 2 tokens with state input and is
    nearly free). Measured on one core at batch 16, k = 100: D 256 / ff 1024 / 4+4+4 layers takes
    1.33 s per step, D 128 / ff 512 / 4+4+4 takes 0.49 s, and the default D 128 / ff 512 / 2+2+2
    0.24 s (1.4 M parameters): ~5x more steps in a 30-minute budget, which matters more than width
    for a low-dim observation. ``ACTConfig.paper()`` is 72.5 M parameters without a backbone.
    """

    obs_type: str = "low_dim"
    """'low_dim' (a feature vector per step) or 'image' (one camera + the low-dim vector)."""
    features: str = "aloha_state"
    """How observations become the low-dim vector: a key of coursekit.data.features.FEATURES (any task)."""
    obs_dim: int = 21
    """Do: low-dim features per step (ALOHA transfer cube: qpos 14 + cube pose 7)."""
    action_dim: int = 14
    """Da: dimension of one action (ALOHA: 14 joint targets)."""
    chunk_size: int = 100
    """k: actions predicted per chunk (paper: 100 at 50 Hz = 2 s)."""
    hidden_dim: int = 128
    """D: transformer width (paper: 512)."""
    ff_dim: int = 512
    """Feed-forward width of every layer (paper: 3200)."""
    n_heads: int = 4
    """Attention heads (paper: 8)."""
    n_encoder_layers: int = 2
    """Layers of the decoder-side transformer encoder (paper: 4)."""
    n_decoder_layers: int = 2
    """Decoder layers, all used (paper: 7; the original code effectively used only the first)."""
    n_vae_encoder_layers: int = 2
    """Layers of the CVAE encoder (paper: 4)."""
    latent_dim: int = 32
    """Size of the style variable z (paper: 32)."""
    dropout: float = 0.1
    """Dropout in every transformer layer (paper: 0.1)."""
    kl_weight: float = 10.0
    """beta: weight of the KL term (paper: 10)."""
    use_vae: bool = True
    """False: a deterministic transformer, z = 0 always and no KL (the paper's "no CVAE" ablation, Sec. V-C)."""
    temporal_ensembling: bool = True
    """Default executor: temporal ensembling (True) or open-loop receding horizon of n_action_steps (False)."""
    ensemble_decay: float = 0.01
    """m in w_i = exp(-m i) for temporal ensembling (paper: 0.01)."""
    n_action_steps: int | None = None
    """Ta when temporal ensembling is off: actions executed per chunk (None: all k, open loop as in the paper)."""
    vision: VisionEncoderConfig | None = None
    """Image backbone (obs_type 'image' only; its stem + residual stages are used, no crop by default)."""

    def __post_init__(self) -> None:
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"ACTConfig.obs_type must be one of {OBS_TYPES}, got {self.obs_type!r}")
        for f in ("obs_dim", "action_dim", "chunk_size", "hidden_dim", "ff_dim", "n_heads", "n_encoder_layers",
                  "n_decoder_layers", "n_vae_encoder_layers", "latent_dim"):
            v = getattr(self, f)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
                raise ValueError(f"ACTConfig.{f} must be a positive integer, got {v!r}")
        if self.hidden_dim % self.n_heads or self.hidden_dim % 4:
            raise ValueError(f"ACTConfig.hidden_dim={self.hidden_dim} must be a multiple of 4 and of n_heads={self.n_heads}")
        if self.n_action_steps is not None and (not isinstance(self.n_action_steps, (int, np.integer))
                                                or not 1 <= self.n_action_steps <= self.chunk_size):
            raise ValueError(f"ACTConfig.n_action_steps must be None or an int in [1, chunk_size={self.chunk_size}], "
                             f"got {self.n_action_steps!r}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"ACTConfig.dropout must be in [0, 1), got {self.dropout!r}")
        for f in ("kl_weight", "ensemble_decay"):
            if not (np.isfinite(getattr(self, f)) and getattr(self, f) >= 0):
                raise ValueError(f"ACTConfig.{f} must be a finite number >= 0, got {getattr(self, f)!r}")
        if self.obs_type == "image" and self.vision is None:
            self.vision = VisionEncoderConfig(crop_size=VisionEncoderConfig().image_size)  # ACT: no crop
        if self.obs_type == "low_dim" and self.vision is not None:
            raise ValueError(f"ACTConfig.vision given for obs_type 'low_dim': {self.vision!r}")
        if self.vision is not None and self.vision.frame_size is not None:  # ACT's trunk reads image_size frames
            raise ValueError(f"ACTConfig.vision.frame_size must be None (ACT encodes frames at image_size "
                             f"{self.vision.image_size}), got {self.vision.frame_size!r}")

    @property
    def n_obs_steps(self) -> int:
        """To: ACT conditions on the current observation only."""
        return 1

    @property
    def horizon(self) -> int:
        """Tp: actions per chunk (= k). Kept on purpose: every policy config answers ``horizon``
        (executors, evaluation and notebook 09 read Tp whatever the head); k stays ACT's own name."""
        return self.chunk_size

    @classmethod
    def paper(cls, **overrides: Any) -> ACTConfig:
        """The paper's size (Zhao et al. 2023, Table VI): D 512, ff 3200, 8 heads, 4 + 4 + 7 layers, k 100, z 32."""
        base = dict(hidden_dim=512, ff_dim=3200, n_heads=8, n_encoder_layers=4, n_decoder_layers=7,
                    n_vae_encoder_layers=4, latent_dim=32, dropout=0.1, chunk_size=100, kl_weight=10.0)
        return cls(**{**base, **overrides})


def low_dim(obs: Mapping[str, Any]) -> Any:
    """The low-dim vector of an observation dict: "obs", or "agent_pos" beside an "image" (the feature
    table's name for it, ``coursekit.data.features``)."""
    for key in ("obs", "agent_pos"):
        if key in obs:
            return obs[key]
    raise ValueError(f"observation dict lacks 'obs' (or 'agent_pos' beside an image); got keys {sorted(obs)}")


class ImageTokens(nn.Module):
    """Camera image -> tokens: ResNet-style trunk, 1x1 conv to D, 2-D sine positions.

    images (B, C, H, W) in [-1, 1] -> tokens (B, h*w, D) and positions (h*w, D). The trunk is the
    stem + residual stages of :class:`coursekit.nn.vision.VisionEncoder` (its spatial-softmax
    head is Diffusion Policy's and is not used here); ACT keeps the whole feature map as tokens.
    """

    def __init__(self, config: VisionEncoderConfig, dim: int) -> None:
        super().__init__()
        encoder = VisionEncoder(config)
        self.config = config
        self.trunk = nn.Sequential(encoder.stem, encoder.stages)
        self.proj = nn.Conv2d(config.widths[-1], dim, kernel_size=1)
        with torch.no_grad():
            h, w = self.trunk(torch.zeros(1, config.in_channels, *config.image_size)).shape[-2:]
        self.register_buffer("pos", sinusoidal_2d(h, w, dim).flatten(1).T.contiguous(), persistent=False)  # (h*w, D)

    def forward(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        feat = self.proj(self.trunk(images))  # (B, D, h, w)
        return feat.flatten(2).transpose(1, 2), self.pos  # (B, h*w, D), (h*w, D)


class ACTPolicy(ChunkPolicy):
    """ACT as a chunk policy: ``compute_loss(batch)`` for training, ``predict_chunk(obs)`` for control.

    Normalisers: "obs" (Do) and "action" (Da), per-dimension mean/std (``fit_normalizers``).
    """

    policy_type = "act"
    config_class = ACTConfig
    config: ACTConfig
    # "paper" (Zhao et al. 2023, Table VI): AdamW lr 1e-5, weight decay 1e-4, batch 8, constant LR,
    # no EMA. "cpu": the same but lr 3e-4 with 200 warm-up steps, batch 16, gradient clipping at
    # 10 and a cosine decay of the LR to 0 over the budget -- deliberate departures: a 30-minute
    # CPU budget allows far fewer steps than the paper's run. Measured (transfer cube, CPU-default
    # ACT, 20 min on one busy core, constant LR, 20 held-out episodes): lr 1e-4 -> 1145 steps,
    # L1 0.127, 0 % strict success; lr 3e-4 -> 2570 steps, L1 0.070, 70 % strict with temporal
    # ensembling. The warm-up keeps post-norm attention stable at the larger LR; the cosine tail
    # (as in Diffusion Policy's recipe) ends a fixed budget on settled weights instead of the last
    # noisy step, since ACT keeps no EMA.
    recipes = {
        "paper": dict(lr=1e-5, weight_decay=1e-4, betas=(0.9, 0.999), lr_schedule="constant", warmup_steps=0,
                      batch_size=8, ema=False),
        "cpu": dict(lr=3e-4, weight_decay=1e-4, betas=(0.9, 0.999), lr_schedule="cosine", warmup_steps=200,
                    batch_size=16, ema=False, grad_clip_norm=10.0),
    }
    eval_overrides = ("temporal_ensembling", "ensemble_decay", "n_action_steps")

    def __init__(self, config: ACTConfig, normalizers: Mapping[str, Normalizer] | None = None) -> None:
        super().__init__(config, normalizers)
        c, D = config, config.hidden_dim
        # --- CVAE encoder q(z | a, o): training only ---------------------------------------
        self.vae_cls = nn.Embedding(1, D)
        self.vae_obs_proj = nn.Linear(c.obs_dim, D)
        self.vae_action_proj = nn.Linear(c.action_dim, D)
        self.vae_encoder = TransformerEncoder(c.n_vae_encoder_layers, D, c.n_heads, c.ff_dim, c.dropout)
        self.vae_latent_proj = nn.Linear(D, 2 * c.latent_dim)  # -> (mu, log sigma^2)
        self.register_buffer("vae_pos", sinusoidal_1d(c.chunk_size + 2, D), persistent=False)  # (k + 2, D)
        # --- decoder side p(a | z, o) --------------------------------------------------------
        self.latent_proj = nn.Linear(c.latent_dim, D)
        self.obs_proj = nn.Linear(c.obs_dim, D)
        self.token_pos = nn.Embedding(2, D)  # learned positions of [z, obs] (ACT's additional_pos_embed)
        self.image_tokens = ImageTokens(c.vision, D) if c.obs_type == "image" else None
        self.transformer = ACTTransformer(D, c.n_heads, c.ff_dim, c.n_encoder_layers, c.n_decoder_layers,
                                          c.chunk_size, c.dropout)
        self.action_head = nn.Linear(D, c.action_dim)

    # ---- normalisation -------------------------------------------------------------------------
    def normalizer_dims(self) -> dict[str, int]:
        return {"obs": self.config.obs_dim, "action": self.config.action_dim}

    def fit_normalizers(self, obs: Mapping[str, Any], action: Any, min_std: float = 0.01) -> None:
        """Mean/std (std clipped at ``min_std``, ACT's 0.01) of obs {"obs": (N, Do)} (image features:
        {"agent_pos": (N, Do), "image": ...}) and action (N, Da)."""
        self.set_normalizers({"obs": MeanStdNormalizer.fit(np.asarray(low_dim(obs)), min_std),
                              "action": MeanStdNormalizer.fit(np.asarray(action), min_std)})

    # ---- the two halves of the CVAE ------------------------------------------------------------
    def encode(self, obs_n: torch.Tensor, action_n: torch.Tensor, is_pad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Posterior q(z | a, o): obs_n (B, Do), action_n (B, k, Da) normalised, is_pad (B, k) -> mu, logvar (B, dz)."""
        B = obs_n.shape[0]
        tokens = torch.cat([self.vae_cls.weight.expand(B, 1, -1),  # (B, 1, D)
                            self.vae_obs_proj(obs_n)[:, None],  # (B, 1, D)
                            self.vae_action_proj(action_n)], dim=1)  # (B, k + 2, D)
        mask = torch.cat([torch.zeros(B, 2, dtype=torch.bool, device=is_pad.device), is_pad], dim=1)  # (B, k + 2)
        cls_out = self.vae_encoder(tokens, self.vae_pos, key_padding_mask=mask)[:, 0]  # (B, D)
        mu, logvar = self.vae_latent_proj(cls_out).chunk(2, dim=-1)  # (B, dz) each
        return mu, logvar

    def decode(self, obs_n: torch.Tensor, z: torch.Tensor, images: torch.Tensor | None = None) -> torch.Tensor:
        """p(a | z, o): obs_n (B, Do), z (B, dz), images (B, C, H, W) in [-1, 1] or None -> chunk (B, k, Da) normalised."""
        src = torch.stack([self.latent_proj(z), self.obs_proj(obs_n)], dim=1)  # (B, 2, D)
        pos = self.token_pos.weight  # (2, D)
        if self.image_tokens is not None:
            if images is None:
                raise ValueError("an image ACT policy needs images (B, C, H, W)")
            img_tok, img_pos = self.image_tokens(images)  # (B, h*w, D), (h*w, D)
            src, pos = torch.cat([src, img_tok], dim=1), torch.cat([pos, img_pos], dim=0)  # (B, 2 + h*w, D)
        h = self.transformer(src, pos)  # (B, k, D)
        return self.action_head(h)  # (B, k, Da)

    # ---- inputs ----------------------------------------------------------------------------------
    def _inputs(self, obs_history: Any) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Raw obs (B, To, Do) or (B, Do), or a dict with "obs" and "image" -> (obs (B, Do), images (B, C, H, W) or None).

        A 2-d input is read as (B, Do), not as an unbatched (To, Do) history: with To = 1 the two
        cannot be told apart, and a batch of environments is the common case.
        """
        c = self.config
        if isinstance(obs_history, Mapping):
            low, img = low_dim(obs_history), obs_history.get("image")
        else:
            low, img = obs_history, None
        obs = as_float_tensor(low, "observation 'obs'", self.device)
        if obs.dim() == 3:
            obs = obs[:, -1]  # (B, Do): ACT sees the current step only
        if obs.dim() != 2 or obs.shape[1] != c.obs_dim:
            raise ValueError(f"observation 'obs' must be (B, To, {c.obs_dim}) or (B, {c.obs_dim}), got {tuple(obs.shape)}")
        images = None
        if c.obs_type == "image":
            if img is None:
                raise ValueError("an image ACT policy needs obs_history['image'] (B, To, C, H, W) or (B, C, H, W)")
            check_values(torch.as_tensor(img), "observation 'image'")  # 0..255 floats would saturate
            images = as_float_tensor(img, "observation 'image'", self.device)
            if images.dim() == 5:
                images = images[:, -1]  # (B, C, H, W)
            images = images.float() / 255.0 if images.dtype == torch.uint8 else images
            images = images * 2.0 - 1.0  # [0, 1] -> [-1, 1]
        return obs, images

    # ---- training --------------------------------------------------------------------------------
    def compute_loss(self, batch: Mapping[str, Any], generator: torch.Generator | None = None,
                     kl_fn: Callable[[torch.Tensor, torch.Tensor], torch.Tensor] = gaussian_kl) -> dict[str, torch.Tensor]:
        """L1 over non-padded steps + beta * KL.

        Batch contract (raw units):
            "obs": (B, Do) or (B, 1, Do) features at time t;  "image": (B, [1,] C, H, W) (image policies).
            "action": (B, k, Da) actions t .. t+k-1 (values at padded steps are ignored).
            "action_is_pad": (B, k) bool, True past the episode end (optional: all False).
        ``generator`` draws the reparameterisation noise; ``kl_fn(mu, logvar) -> ()`` is the KL term
        (the library's :func:`gaussian_kl` unless a student's version is passed in, chapter 7).
        Returns {"loss", "l1", "kl"} scalars ("kl" is 0 when ``use_vae`` is False).
        """
        self._require_normalizers()
        c = self.config
        obs, images = self._inputs({k: batch[k] for k in ("obs", "agent_pos", "image") if k in batch})
        action = as_float_tensor(batch["action"], "batch 'action'", self.device)
        if action.shape != (obs.shape[0], c.chunk_size, c.action_dim):
            raise ValueError(f"batch 'action' must be (B={obs.shape[0]}, k={c.chunk_size}, Da={c.action_dim}), got {tuple(action.shape)}")
        is_pad = batch.get("action_is_pad")
        is_pad = (torch.zeros(action.shape[:2], dtype=torch.bool, device=self.device) if is_pad is None
                  else torch.as_tensor(is_pad, device=self.device).bool())  # (B, k)
        obs_n = self.normalizers["obs"].normalize(obs)  # (B, Do)
        action_n = self.normalizers["action"].normalize(action).masked_fill(is_pad[..., None], 0.0)  # (B, k, Da)
        if c.use_vae:
            mu, logvar = self.encode(obs_n, action_n, is_pad)
            eps = torch.randn(mu.shape, generator=generator, device=generator.device if generator else mu.device)
            z = mu + (0.5 * logvar).exp() * eps.to(mu.device)  # reparameterisation (Kingma & Welling 2014)
            kl = kl_fn(mu, logvar)
        else:
            z = torch.zeros(obs.shape[0], c.latent_dim, device=self.device)
            kl = torch.zeros((), device=self.device)
        pred = self.decode(obs_n, z, images)  # (B, k, Da)
        valid = (~is_pad)[..., None].float()  # (B, k, 1)
        l1 = ((pred - action_n).abs() * valid).sum() / (valid.sum() * c.action_dim).clamp(min=1.0)
        return {"loss": l1 + c.kl_weight * kl, "l1": l1, "kl": kl}

    # ---- deployment ----------------------------------------------------------------------------
    @torch.no_grad()
    def predict_chunk(self, obs_history: Any, *, generator: torch.Generator | None = None) -> Any:
        """Raw observation -> raw chunk with z = 0 (the prior mean), in eval mode (no dropout).

        Deterministic: ``generator`` is accepted (the shared contract) and unused.

        obs_history: (B, To, Do) with To = 1 (only the last step is read if To > 1) or (B, Do);
        image policies: a dict {"obs": ..., "image": (B, To, C, H, W) uint8 or float in [0, 1]}.
        Returns (B, k, Da); numpy in, numpy out; tensors in, tensors out.
        """
        self._require_normalizers()
        obs, images = self._inputs(obs_history)
        was_training = self.training
        self.eval()
        try:
            z = torch.zeros(obs.shape[0], self.config.latent_dim, device=self.device)  # prior mean
            chunk = self.normalizers["action"].unnormalize(self.decode(self.normalizers["obs"].normalize(obs), z, images))
        finally:
            self.train(was_training)
        first = low_dim(obs_history) if isinstance(obs_history, Mapping) else obs_history
        return chunk.cpu().numpy() if isinstance(first, np.ndarray) else chunk  # (B, k, Da)

    # ---- training setup and execution ------------------------------------------------------------
    @classmethod
    def make_config(cls, preset: str | None = None, **fields: Any) -> ACTConfig:
        """ACTConfig from the data's dimensions; ``preset`` "cpu" (default size) or "paper" (Table VI)."""
        if preset not in (None, "cpu", "paper"):
            raise ValueError(f"ACT preset must be 'cpu' or 'paper', got {preset!r}")
        return ACTConfig.paper(**fields) if preset == "paper" else ACTConfig(**fields)

    def make_batcher(self, obs: Mapping[str, Any], action: Any, episode_ends: Any, *, batch_size: int,
                     seed: int = 0, device: Any = "cpu") -> ChunkBatcher:
        """One sample per step: ``{"obs": (B, Do), "action": (B, k, Da), "action_is_pad": (B, k)}`` (and
        "image": (B, 3, H, W) uint8 for image features, whose "agent_pos" becomes "obs")."""
        obs = {"obs": low_dim(obs), **({"image": obs["image"]} if "image" in obs else {})}
        return ChunkBatcher(obs, action, episode_ends, chunk_size=self.config.chunk_size, batch_size=batch_size,
                            seed=seed, device=device)

    def execution_spec(self) -> ExecutionSpec:
        """Temporal ensembling with m = ``ensemble_decay`` (``temporal_ensembling``), else receding horizon
        of Ta = ``n_action_steps`` (None: all k, open loop as in the paper); To = 1."""
        c = self.config
        return ExecutionSpec(n_obs_steps=1, horizon=c.chunk_size, n_action_steps=c.n_action_steps or c.chunk_size,
                             temporal_ensembling=c.temporal_ensembling, ensemble_decay=c.ensemble_decay)
