"""Fixed sinusoidal position embeddings, 1-D (token sequences) and 2-D (image feature maps).

1-D (Vaswani et al. 2017, Sec. 3.5)::

    pe[p, 2i]   = sin(p / 10000^(2i / dim))
    pe[p, 2i+1] = cos(p / 10000^(2i / dim))

2-D (DETR, Carion et al. 2020, as used by ACT for its ResNet feature tokens): half of the
channels encode the row y, half the column x, each with the 1-D formula on positions
normalised to (0, 2 pi] (DETR's ``normalize=True``). ACT's CVAE encoder uses the 1-D table
for its [CLS, qpos, a_1..a_k] tokens; its decoder-side encoder uses the 2-D one for image tokens.
"""

from __future__ import annotations

import math

import torch


def sinusoidal_1d(n_positions: int, dim: int, base: float = 10000.0) -> torch.Tensor:
    """The (n_positions, dim) table of 1-D sine/cosine embeddings; dim must be even."""
    if n_positions < 1 or dim < 2 or dim % 2:
        raise ValueError(f"need n_positions >= 1 and an even dim >= 2, got n_positions={n_positions}, dim={dim}")
    pos = torch.arange(n_positions, dtype=torch.float64)[:, None]  # (P, 1)
    freq = base ** (-torch.arange(0, dim, 2, dtype=torch.float64) / dim)  # (dim/2,)
    angle = pos * freq[None, :]  # (P, dim/2)
    pe = torch.stack([angle.sin(), angle.cos()], dim=-1).reshape(n_positions, dim)  # (P, dim): sin, cos interleaved
    return pe.float()


def sinusoidal_2d(height: int, width: int, dim: int, base: float = 10000.0) -> torch.Tensor:
    """The (dim, height, width) table of 2-D sine embeddings: first dim/2 channels y, last dim/2 x.

    Positions run 1..H (1..W) scaled to (0, 2 pi] as in DETR's ``PositionEmbeddingSine`` with
    ``normalize=True``, so a map of any size spans the same range of angles.
    """
    if height < 1 or width < 1 or dim < 4 or dim % 4:
        raise ValueError(f"need height, width >= 1 and dim a multiple of 4, got height={height}, width={width}, dim={dim}")
    half = dim // 2
    freq = base ** (-torch.arange(0, half, 2, dtype=torch.float64) / half)  # (half/2,)
    y = torch.arange(1, height + 1, dtype=torch.float64) / height * 2 * math.pi  # (H,)
    x = torch.arange(1, width + 1, dtype=torch.float64) / width * 2 * math.pi  # (W,)
    ay, ax = y[:, None] * freq, x[:, None] * freq  # (H, half/2), (W, half/2)
    pe_y = torch.stack([ay.sin(), ay.cos()], dim=-1).reshape(height, half)  # (H, half)
    pe_x = torch.stack([ax.sin(), ax.cos()], dim=-1).reshape(width, half)  # (W, half)
    pe = torch.cat([pe_y[:, None, :].expand(height, width, half),
                    pe_x[None, :, :].expand(height, width, half)], dim=-1)  # (H, W, dim)
    return pe.permute(2, 0, 1).float().contiguous()  # (dim, H, W)
