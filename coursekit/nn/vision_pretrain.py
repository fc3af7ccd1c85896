"""Stage 1 of the two-stage pixel route: teach an image encoder to read the scene before the policy.

Training Diffusion Policy end to end from pixels asks one loss (the denoising error of a chunk)
to shape both the encoder and the U-Net; on a CPU that is most of the budget spent on the encoder
(chapter 12). A simulator gives the scene's state for free, so the encoder can first be trained
with plain supervision: regress a target the policy will need (for PushT the block's keypoints,
``coursekit.data.features.pusht_keypoints``) from a frame, through the encoder's spatial-softmax
features and a linear read-out. The trained encoder is then frozen (or fine-tuned) inside the
policy. This is a departure from Chi et al. 2023 (end to end, from scratch); Levine et al. 2016
pre-train their spatial-softmax encoder on object poses in the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn


@dataclass(frozen=True)
class PretrainConfig:
    """Optimisation of the supervised encoder pre-training."""

    steps: int = 2000
    """Optimiser steps."""
    batch_size: int = 128
    """Frames per step."""
    lr: float = 1e-3
    """AdamW learning rate (cosine decay to 0 over ``steps``)."""
    weight_decay: float = 1e-6
    """AdamW weight decay."""
    seed: int = 0
    """Seeds the read-out's initialisation, the batch order and the random crops."""

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(f"PretrainConfig.{name} must be a positive int, got {getattr(self, name)!r}")
        if not (np.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"PretrainConfig.lr must be a finite number > 0, got {self.lr!r}")


def _check(images: np.ndarray, targets: np.ndarray, encoder: nn.Module) -> None:
    size = tuple(encoder.config.input_size)
    if images.ndim != 4 or images.dtype != np.uint8 or images.shape[1] != encoder.config.in_channels \
            or tuple(images.shape[2:]) != size:
        raise ValueError(f"images must be (N, {encoder.config.in_channels}, {size[0]}, {size[1]}) uint8 frames, "
                         f"got {images.shape} {images.dtype}")
    if targets.ndim != 2 or len(targets) != len(images) or not np.isfinite(targets).all():
        raise ValueError(f"targets must be finite (N={len(images)}, D), got {targets.shape} "
                         f"(finite: {bool(np.isfinite(targets).all())})")


def to_unit(images: torch.Tensor) -> torch.Tensor:
    """uint8 frames (B, C, H, W) -> float in [-1, 1], the encoder's input range."""
    return images.float() / 127.5 - 1.0


def pretrain_encoder(encoder: nn.Module, images: np.ndarray, targets: np.ndarray,
                     config: PretrainConfig = PretrainConfig()) -> dict[str, object]:
    """Train ``encoder`` in place to predict ``targets`` from ``images``; returns the read-out and losses.

    Args:
        encoder: a :class:`coursekit.nn.vision.VisionEncoder` (random crops in train mode).
        images: (N, C, H, W) uint8 frames at the encoder's ``input_size``.
        targets: (N, D) what each frame shows (e.g. the block's keypoints); standardised here.
    Returns {"readout": nn.Linear(feature_dim, D), "mean": (D,), "std": (D,), "loss": [per-step MSE]}:
    ``readout(encoder(x)) * std + mean`` predicts the targets.
    """
    _check(images, targets, encoder)
    gen = torch.Generator().manual_seed(config.seed)
    mean, std = targets.mean(0), targets.std(0) + 1e-6  # (D,) each
    y_all = torch.as_tensor((targets - mean) / std, dtype=torch.float32)  # (N, D)
    x_all = torch.as_tensor(images)  # (N, C, H, W) uint8, shared with numpy
    torch.manual_seed(config.seed)
    readout = nn.Linear(encoder.config.feature_dim, targets.shape[1])
    params = [*encoder.parameters(), *readout.parameters()]
    opt = torch.optim.AdamW(params, lr=config.lr, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 0.5 * (1 + np.cos(np.pi * s / config.steps)))
    encoder.train()
    losses = []
    for _ in range(config.steps):
        idx = torch.randint(0, len(x_all), (config.batch_size,), generator=gen)  # (B,)
        pred = readout(encoder(to_unit(x_all[idx]), generator=gen))  # (B, D)
        loss = torch.mean((pred - y_all[idx]) ** 2)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        losses.append(float(loss.detach()))
    encoder.eval()
    return {"readout": readout, "mean": mean, "std": std, "loss": losses}


@torch.no_grad()
def predict_targets(encoder: nn.Module, readout: nn.Module, mean: np.ndarray, std: np.ndarray,
                    images: np.ndarray, batch_size: int = 256) -> np.ndarray:
    """(N, C, H, W) uint8 frames -> (N, D) predicted targets (encoder in eval mode: centre crop)."""
    encoder.eval()
    out = [readout(encoder(to_unit(torch.as_tensor(images[i:i + batch_size])))).numpy()
           for i in range(0, len(images), batch_size)]  # each (b, D)
    return np.concatenate(out) * std + mean


def freeze(encoder: nn.Module) -> nn.Module:
    """Stop gradients into ``encoder`` (stage 2 trains the policy on its fixed features)."""
    encoder.requires_grad_(False)
    return encoder
