"""FiLM: feature-wise linear modulation (Perez et al. 2018), Diffusion Policy's conditioning.

Every residual block of the 1-D U-Net turns the global condition (diffusion-step embedding + observation
features) into one scale and one bias per channel and applies them to all time steps:
``out = scale * h + bias``. This is the ``cond_predict_scale=True`` variant of Chi et al. (2023, sec. 3.4),
with the condition passed through Mish before the linear map as in their code. Note the scale is used
as is (not ``1 + scale``), as in the original.

``FiLM`` is exercise "film"; ``ConditionalUnet1D(film_cls=...)`` takes a student's class.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class FiLM(nn.Module):
    """Per-channel affine modulation of a (B, C, L) feature map by a (B, cond_dim) condition.

        e     = W mish(cond) + b                  (self.linear: cond_dim -> 2 * channels)
        scale = e[:, :channels],  bias = e[:, channels:]                     # (B, C) each
        out   = scale[:, :, None] * h + bias[:, :, None]                     # (B, C, L)

    ``__init__`` must create exactly one layer, ``self.linear = nn.Linear(cond_dim, 2 * channels)``
    (its first ``channels`` outputs are the scales, the last ``channels`` the biases); ``forward``
    applies Mish to ``cond`` (``F.mish``), then ``self.linear``, then the affine map above.

    Args:
        cond_dim: size of the condition vector.
        channels: C, the number of feature channels to modulate.
    """

    def __init__(self, cond_dim: int, channels: int) -> None:
        super().__init__()
        for name, v in (("cond_dim", cond_dim), ("channels", channels)):
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"FiLM {name} must be a positive int, got {v!r}")
        self.cond_dim = cond_dim
        self.channels = channels
        # BEGIN SOLUTION
        self.linear = nn.Linear(cond_dim, 2 * channels)
        # END SOLUTION

    def forward(self, h: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """Modulate h (B, C, L) with cond (B, cond_dim); returns (B, C, L)."""
        if h.ndim != 3 or h.shape[1] != self.channels:
            raise ValueError(f"FiLM expects h of shape (B, {self.channels}, L), got {tuple(h.shape)}")
        if cond.ndim != 2 or cond.shape != (h.shape[0], self.cond_dim):
            raise ValueError(f"FiLM expects cond of shape ({h.shape[0]}, {self.cond_dim}), got {tuple(cond.shape)}")
        # BEGIN SOLUTION
        e = self.linear(F.mish(cond))  # (B, 2C)
        scale, bias = e[:, : self.channels], e[:, self.channels:]  # (B, C) each
        out = scale.unsqueeze(-1) * h + bias.unsqueeze(-1)  # (B, C, L)
        # END SOLUTION
        return out
