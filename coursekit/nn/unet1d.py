"""The conditional 1-D temporal U-Net of Diffusion Policy (Chi et al. 2023, sec. 3.4, fig. 3 / A.1).

A U-Net over the TIME axis of an action chunk: channels are features, length is Tp. Each level of the
down path has two FiLM-conditioned residual blocks and a stride-2 convolution; the middle has two
blocks; the up path concatenates the skip connection, applies two blocks and a transposed convolution.
The global condition is ``[step embedding, flattened To observation features]``.

Layout (down_dims = (d0, d1, d2), Tp = 16)::

    (B, Da, 16) -res,res-> (B, d0, 16) -down-> (B, d0, 8) -res,res-> (B, d1, 8) -down-> (B, d1, 4)
      -res,res-> (B, d2, 4)  [no downsampling at the last level]  -mid,mid-> (B, d2, 4)
      cat skip (B, 2 d2, 4) -res,res-> (B, d1, 4) -up-> (B, d1, 8)
      cat skip (B, 2 d1, 8) -res,res-> (B, d0, 8) -up-> (B, d0, 16)  -final-> (B, Da, 16)

This follows the original code's structure exactly, including that the first level's skip is never
used (it is pushed, never popped) and that the last up level still upsamples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from coursekit.nn.film import FiLM


@dataclass(frozen=True)
class UNet1DConfig:
    """Sizes of the conditional 1-D U-Net (the input/condition sizes are constructor arguments)."""

    down_dims: tuple[int, ...] = (64, 128, 256)
    """Channels per level (paper low-dim: 256/512/1024; image: 512/1024/2048)."""
    kernel_size: int = 5
    """Temporal convolution kernel (odd, so padding k // 2 keeps the length)."""
    n_groups: int = 8
    """GroupNorm groups in every Conv1dBlock (each down_dim must be divisible by it)."""
    diffusion_step_embed_dim: int = 128
    """d, the size of the diffusion-step embedding (paper: 256); even, for sin/cos halves."""

    def __post_init__(self) -> None:
        dims = tuple(self.down_dims)
        if len(dims) < 1 or any(not isinstance(d, int) or d < 1 for d in dims):
            raise ValueError(f"down_dims must be a non-empty tuple of positive ints, got {self.down_dims!r}")
        object.__setattr__(self, "down_dims", dims)
        if not isinstance(self.kernel_size, int) or self.kernel_size < 1 or self.kernel_size % 2 == 0:
            raise ValueError(f"kernel_size must be a positive odd int, got {self.kernel_size!r}")
        if not isinstance(self.n_groups, int) or self.n_groups < 1 or any(d % self.n_groups for d in dims):
            raise ValueError(f"every down_dim must be divisible by n_groups; got down_dims={dims}, "
                             f"n_groups={self.n_groups!r}")
        d = self.diffusion_step_embed_dim
        if not isinstance(d, int) or d < 4 or d % 2:
            raise ValueError(f"diffusion_step_embed_dim must be an even int >= 4, got {d!r}")

    @classmethod
    def preset(cls, name: str) -> "UNet1DConfig":
        """"cpu" (default: 64/128/256, ~4-5 M params), "paper_lowdim" (65.8 M), "paper_image"."""
        presets = {
            "cpu": cls(),
            "paper_lowdim": cls(down_dims=(256, 512, 1024), kernel_size=5, diffusion_step_embed_dim=256),
            "paper_image": cls(down_dims=(512, 1024, 2048), kernel_size=5, diffusion_step_embed_dim=256),
        }
        if name not in presets:
            raise ValueError(f"unknown U-Net preset {name!r}; expected one of {sorted(presets)}")
        return presets[name]


class SinusoidalPosEmb(nn.Module):
    """Transformer-style sinusoidal embedding of a scalar step: (B,) -> (B, dim), [sin | cos] halves."""

    def __init__(self, dim: int) -> None:
        super().__init__()
        self.dim = dim

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        half = self.dim // 2
        freqs = torch.exp(torch.arange(half, device=t.device) * (-math.log(10000.0) / (half - 1)))  # (half,)
        args = t.float()[:, None] * freqs[None, :]  # (B, half)
        return torch.cat([args.sin(), args.cos()], dim=-1)  # (B, dim)


class Conv1dBlock(nn.Module):
    """Conv1d(kernel k, padding k // 2) -> GroupNorm -> Mish: (B, C_in, L) -> (B, C_out, L)."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, n_groups: int = 8) -> None:
        super().__init__()
        self.block = nn.Sequential(
            nn.Conv1d(in_channels, out_channels, kernel_size, padding=kernel_size // 2),
            nn.GroupNorm(n_groups, out_channels),
            nn.Mish(),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.block(x)


class ConditionalResidualBlock1D(nn.Module):
    """Two Conv1dBlocks with FiLM after the first, plus a (1x1-conv when channels change) skip.

    forward(x (B, C_in, L), cond (B, cond_dim)) -> (B, C_out, L).
    """

    def __init__(self, in_channels: int, out_channels: int, cond_dim: int, kernel_size: int = 5,
                 n_groups: int = 8, film_cls: type[nn.Module] = FiLM) -> None:
        super().__init__()
        self.block1 = Conv1dBlock(in_channels, out_channels, kernel_size, n_groups)
        self.film = film_cls(cond_dim, out_channels)
        self.block2 = Conv1dBlock(out_channels, out_channels, kernel_size, n_groups)
        self.skip = nn.Conv1d(in_channels, out_channels, 1) if in_channels != out_channels else nn.Identity()

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        h = self.film(self.block1(x), cond)  # (B, C_out, L)
        return self.block2(h) + self.skip(x)  # (B, C_out, L)


class ConditionalUnet1D(nn.Module):
    """Epsilon model over action chunks: (x_t (B, Tp, Da), t, global_cond) -> eps_hat (B, Tp, Da).

    Args:
        input_dim: Da, the action dimension.
        global_cond_dim: size of the observation condition (e.g. To * obs_feature_dim), 0 for none.
        config: sizes (``UNet1DConfig()`` = the CPU default).
        film_cls: the FiLM class, ``film_cls(cond_dim, channels)`` (a student's in chapter 3).
    """

    def __init__(self, input_dim: int, global_cond_dim: int, config: UNet1DConfig | None = None,
                 film_cls: type[nn.Module] = FiLM) -> None:
        super().__init__()
        if not isinstance(input_dim, int) or input_dim < 1:
            raise ValueError(f"input_dim (Da) must be a positive int, got {input_dim!r}")
        if not isinstance(global_cond_dim, int) or global_cond_dim < 0:
            raise ValueError(f"global_cond_dim must be an int >= 0, got {global_cond_dim!r}")
        self.config = cfg = config if config is not None else UNet1DConfig()
        self.input_dim, self.global_cond_dim = input_dim, global_cond_dim
        d, k, g = cfg.diffusion_step_embed_dim, cfg.kernel_size, cfg.n_groups
        # Step embedding: sinusoidal -> Linear(4d) -> Mish -> Linear(d) (sec. 3.4 / original code).
        self.step_encoder = nn.Sequential(SinusoidalPosEmb(d), nn.Linear(d, 4 * d), nn.Mish(), nn.Linear(4 * d, d))
        cond_dim = d + global_cond_dim

        def res(cin: int, cout: int) -> ConditionalResidualBlock1D:
            return ConditionalResidualBlock1D(cin, cout, cond_dim, k, g, film_cls)

        dims = (input_dim, *cfg.down_dims)
        in_out = list(zip(dims[:-1], dims[1:]))  # [(Da, d0), (d0, d1), (d1, d2)]
        n = len(in_out)
        self.down = nn.ModuleList()
        for i, (cin, cout) in enumerate(in_out):
            last = i == n - 1
            down = nn.Identity() if last else nn.Conv1d(cout, cout, 3, stride=2, padding=1)
            self.down.append(nn.ModuleList([res(cin, cout), res(cout, cout), down]))
        mid = cfg.down_dims[-1]
        self.mid = nn.ModuleList([res(mid, mid), res(mid, mid)])
        self.up = nn.ModuleList()
        for cin, cout in reversed(in_out[1:]):  # [(d1, d2), (d0, d1)]: back up to d0
            up = nn.ConvTranspose1d(cin, cin, 4, stride=2, padding=1)
            self.up.append(nn.ModuleList([res(2 * cout, cin), res(cin, cin), up]))
        d0 = cfg.down_dims[0]
        self.final = nn.Sequential(Conv1dBlock(d0, d0, k, g), nn.Conv1d(d0, input_dim, 1))

    @property
    def length_multiple(self) -> int:
        """Tp must be a multiple of this (one halving per level but the last)."""
        return 2 ** (len(self.config.down_dims) - 1)

    def forward(self, sample: torch.Tensor, timestep: torch.Tensor | int,
                global_cond: torch.Tensor | None = None) -> torch.Tensor:
        """sample (B, Tp, Da), timestep (B,) long or a scalar, global_cond (B, global_cond_dim) -> (B, Tp, Da)."""
        if sample.ndim != 3 or sample.shape[-1] != self.input_dim:
            raise ValueError(f"sample must be (B, Tp, {self.input_dim}), got {tuple(sample.shape)}")
        B, Tp, _ = sample.shape
        if Tp % self.length_multiple:
            raise ValueError(f"horizon Tp={Tp} must be a multiple of {self.length_multiple} "
                             f"for down_dims={self.config.down_dims}")
        t = torch.as_tensor(timestep, device=sample.device)
        t = t.expand(B) if t.ndim == 0 else t  # (B,)
        if t.shape != (B,):
            raise ValueError(f"timestep must be a scalar or shape ({B},), got {tuple(t.shape)}")
        cond = self.step_encoder(t)  # (B, d)
        if self.global_cond_dim:
            if global_cond is None or global_cond.shape != (B, self.global_cond_dim):
                got = None if global_cond is None else tuple(global_cond.shape)
                raise ValueError(f"global_cond must be ({B}, {self.global_cond_dim}), got {got}")
            cond = torch.cat([cond, global_cond.to(cond.dtype)], dim=-1)  # (B, d + global_cond_dim)

        x = sample.transpose(1, 2)  # (B, Da, Tp): convolve over time
        skips = []
        for res1, res2, down in self.down:
            x = res2(res1(x, cond), cond)
            skips.append(x)
            x = down(x)
        for block in self.mid:
            x = block(x, cond)
        for res1, res2, up in self.up:
            x = torch.cat([x, skips.pop()], dim=1)  # (B, 2C, L)
            x = up(res2(res1(x, cond), cond))
        x = self.final(x)  # (B, Da, Tp)
        return x.transpose(1, 2)  # (B, Tp, Da)
