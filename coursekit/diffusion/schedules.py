"""Noise schedules: how much signal survives after t forward-noising steps.

The forward process (Ho et al. 2020, eq. 2) adds Gaussian noise with variance ``beta_t`` at step t;
after t steps the signal scale is ``sqrt(abar_t)`` with ``abar_t = prod_{s<=t} (1 - beta_s)``.
Diffusion Policy (Chi et al. 2023) uses T = 100 steps and the cosine schedule of Nichol & Dhariwal
(2021, eq. 17), which ``diffusers`` calls ``"squaredcos_cap_v2"``: ``abar`` follows
``f(t) = cos^2(((t / T) + s) / (1 + s) * pi / 2)`` and each beta is capped at 0.999.

Timestep indices run 0..T-1 as in ``diffusers``: index t is the (t+1)-th noising step, so t = 0 is
the least noisy and t = T-1 the noisiest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

BETA_SCHEDULES = ("squaredcos_cap_v2", "linear")


def cosine_alpha_bar(t: float | np.ndarray, s: float = 0.008) -> float | np.ndarray:
    """The continuous cosine schedule ``f(t) = cos^2((t + s) / (1 + s) * pi / 2)``, t in [0, 1].

    Nichol & Dhariwal (2021), eq. 17 (they divide by f(0); diffusers' discretisation only uses ratios
    f(t2) / f(t1), so the normalisation cancels).
    """
    return np.cos((np.asarray(t, dtype=np.float64) + s) / (1.0 + s) * math.pi / 2.0) ** 2


@dataclass
class NoiseSchedule:
    """A discrete variance schedule: ``betas``, ``alphas = 1 - betas``, ``alphas_cumprod`` (each (T,)).

    The three tensors are CPU float32 (computed in float64 first); index them with a timestep tensor
    and move the result to your data's device.
    """

    num_train_timesteps: int = 100
    """T, the number of forward noising steps (Diffusion Policy: 100)."""
    beta_schedule: str = "squaredcos_cap_v2"
    """"squaredcos_cap_v2" (cosine, Nichol & Dhariwal 2021) or "linear" (Ho et al. 2020)."""
    beta_start: float = 1e-4
    """First beta of the linear schedule (ignored by the cosine schedule)."""
    beta_end: float = 0.02
    """Last beta of the linear schedule (ignored by the cosine schedule)."""
    max_beta: float = 0.999
    """Cap on each beta of the cosine schedule (its last steps would otherwise reach beta = 1)."""

    betas: torch.Tensor = field(init=False, repr=False)
    alphas: torch.Tensor = field(init=False, repr=False)
    alphas_cumprod: torch.Tensor = field(init=False, repr=False)

    def __post_init__(self) -> None:
        T = self.num_train_timesteps
        if not isinstance(T, int) or isinstance(T, bool) or T < 1:
            raise ValueError(f"num_train_timesteps must be a positive int, got {T!r}")
        if self.beta_schedule not in BETA_SCHEDULES:
            raise ValueError(f"beta_schedule must be one of {BETA_SCHEDULES}, got {self.beta_schedule!r}")
        if not 0.0 < self.max_beta < 1.0:
            raise ValueError(f"max_beta must lie in (0, 1), got {self.max_beta!r}")
        if self.beta_schedule == "linear":
            if not 0.0 < self.beta_start <= self.beta_end < 1.0:
                raise ValueError("linear schedule needs 0 < beta_start <= beta_end < 1, got "
                                 f"beta_start={self.beta_start!r}, beta_end={self.beta_end!r}")
            betas = np.linspace(self.beta_start, self.beta_end, T, dtype=np.float64)
        else:
            # beta_t = 1 - f((t+1)/T) / f(t/T), capped (Nichol & Dhariwal 2021, sec. 3.2).
            grid = np.arange(T + 1, dtype=np.float64) / T
            f = cosine_alpha_bar(grid)
            betas = np.minimum(1.0 - f[1:] / f[:-1], self.max_beta)
        alphas = 1.0 - betas
        self.betas = torch.as_tensor(betas, dtype=torch.float32)
        self.alphas = torch.as_tensor(alphas, dtype=torch.float32)
        self.alphas_cumprod = torch.as_tensor(np.cumprod(alphas), dtype=torch.float32)

    def snr(self) -> torch.Tensor:
        """Signal-to-noise ratio ``abar_t / (1 - abar_t)`` per timestep, shape (T,)."""
        return self.alphas_cumprod / (1.0 - self.alphas_cumprod)
