"""A 1-D two-mode toy for flow matching: the exact velocity field and a tiny learned one.

Data: a Gaussian mixture a0 ~ sum_k w_k N(mu_k, s_k^2). Along pi0's path x_t = t e + (1 - t) a0
(t = 1 noise, t = 0 data) the marginal velocity has a closed form, because (a0, e, x_t) are
jointly Gaussian within each component k::

    x_t | k  ~ N(m_k, V_k),     m_k = (1 - t) mu_k,   V_k = (1 - t)^2 s_k^2 + t^2
    E[a0 | x_t, k] = mu_k + (1 - t) s_k^2 / V_k * (x_t - m_k)
    E[e  | x_t, k] = t / V_k * (x_t - m_k)
    v*(x_t, t) = sum_k p(k | x_t) (E[e | x_t, k] - E[a0 | x_t, k]),   p(k | x_t) ~ w_k N(x_t; m_k, V_k)

That is the field a perfectly trained flow-matching network learns (the loss's minimiser). At
t = 1, p(k | x) = w_k and v* = x - sum_k w_k mu_k: one Euler step from any noise lands on the
mean of the data -- the regression answer.

``VelocityMLP`` + ``train_toy_flow`` learn the same field from samples in a few seconds on a CPU.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
import torch.nn as nn

from coursekit.flow.loss import flow_loss, flow_matching_loss


@dataclass(frozen=True)
class Mixture1D:
    """A 1-D Gaussian mixture: weights w_k (summing to 1), means mu_k, standard deviations s_k."""

    weights: tuple[float, ...] = (0.3, 0.7)
    """w_k, mode probabilities (positive, summing to 1)."""
    means: tuple[float, ...] = (-2.0, 2.0)
    """mu_k, mode centres."""
    stds: tuple[float, ...] = (0.25, 0.25)
    """s_k, mode widths (> 0)."""

    def __post_init__(self) -> None:
        if not len(self.weights) == len(self.means) == len(self.stds) >= 1:
            raise ValueError(f"weights, means, stds must have the same length >= 1, got {self.weights}, "
                             f"{self.means}, {self.stds}")
        if min(self.weights) <= 0 or abs(sum(self.weights) - 1.0) > 1e-6:
            raise ValueError(f"weights must be positive and sum to 1, got {self.weights}")
        if min(self.stds) <= 0:
            raise ValueError(f"stds must be > 0, got {self.stds}")

    @property
    def mean(self) -> float:
        """E[a0] = sum_k w_k mu_k."""
        return float(sum(w * m for w, m in zip(self.weights, self.means)))

    def sample(self, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """n samples, (n, 1) float32."""
        k = torch.multinomial(torch.tensor(self.weights), n, replacement=True, generator=generator)  # (n,)
        z = torch.randn(n, generator=generator)  # (n,)
        return (torch.tensor(self.means)[k] + torch.tensor(self.stds)[k] * z).unsqueeze(-1)  # (n, 1)

    def velocity(self, x: torch.Tensor, t: torch.Tensor, cond: object = None) -> torch.Tensor:
        """The exact marginal velocity v*(x, t) (see module docstring): x (B, 1), t (B,) -> (B, 1)."""
        x = x.double()
        t = t.double().reshape(-1, 1)  # (B, 1)
        mu = torch.tensor(self.means, dtype=torch.float64)[None, :]  # (1, K)
        s2 = torch.tensor(self.stds, dtype=torch.float64)[None, :] ** 2  # (1, K)
        w = torch.tensor(self.weights, dtype=torch.float64)[None, :]  # (1, K)
        m = (1 - t) * mu  # (B, K)
        var = (1 - t) ** 2 * s2 + t ** 2  # (B, K)
        logp = torch.log(w) - 0.5 * (x - m) ** 2 / var - 0.5 * torch.log(2 * math.pi * var)  # (B, K)
        post = torch.softmax(logp, dim=-1)  # (B, K) p(k | x_t)
        e_a0 = mu + (1 - t) * s2 / var * (x - m)  # (B, K)
        e_e = t / var * (x - m)  # (B, K)
        return (post * (e_e - e_a0)).sum(-1, keepdim=True).float()  # (B, 1)


class VelocityMLP(nn.Module):
    """v_theta(x, t) for 1-D data: [x, sin/cos features of t] -> MLP -> (B, 1)."""

    def __init__(self, hidden: int = 64, n_freqs: int = 4) -> None:
        super().__init__()
        self.register_buffer("freqs", math.pi * 2.0 ** torch.arange(n_freqs, dtype=torch.float32) / 2)  # (F,)
        self.net = nn.Sequential(nn.Linear(1 + 1 + 2 * n_freqs, hidden), nn.SiLU(), nn.Linear(hidden, hidden), nn.SiLU(),
                                 nn.Linear(hidden, 1))

    def forward(self, x: torch.Tensor, t: torch.Tensor, cond: object = None) -> torch.Tensor:
        """x (B, 1), t (B,) in [0, 1] -> v (B, 1); ``cond`` is ignored (unconditional toy)."""
        tf = t.reshape(-1, 1).to(x.dtype) * self.freqs  # (B, F)
        return self.net(torch.cat([x, t.reshape(-1, 1).to(x.dtype), tf.sin(), tf.cos()], dim=-1))


def train_toy_flow(mixture: Mixture1D, steps: int = 1500, batch_size: int = 512, lr: float = 3e-3,
                   seed: int = 0, time_sampling: str = "uniform", hidden: int = 64,
                   losses: list[float] | None = None, loss_fn: Callable[..., torch.Tensor] = flow_matching_loss,
                   ) -> VelocityMLP:
    """Fit a ``VelocityMLP`` to ``mixture`` with the flow-matching loss (Adam, cosine LR); deterministic by seed.

    Args:
        mixture: the data distribution.
        steps, batch_size, lr: optimiser budget (1500 x 512 takes a few seconds on one CPU thread).
        seed: seeds the weights, the data and the loss's t and e.
        time_sampling: "uniform" (default for the toy: every time matters for the plot) or "beta".
        losses: if given, the loss of every step is appended to it.
        loss_fn: ``(model, a0, cond, t, noise) -> scalar``: the library's loss or a student's.
    """
    if not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a positive int, got {steps!r}")
    g = torch.Generator().manual_seed(seed)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = VelocityMLP(hidden)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=steps)
    with torch.enable_grad():  # also when called under torch.no_grad()
        for _ in range(steps):
            a0 = mixture.sample(batch_size, generator=g)  # (B, 1)
            loss = flow_loss(model, a0, None, time_sampling, generator=g, loss_fn=loss_fn)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            if losses is not None:
                losses.append(float(loss.detach()))
    return model.eval()


def mode_fractions(samples: torch.Tensor, boundaries: Sequence[float]) -> list[float]:
    """Fraction of samples (N, 1) in each interval cut by the sorted ``boundaries`` (len K-1 for K modes)."""
    idx = torch.bucketize(samples.reshape(-1).contiguous(), torch.tensor(sorted(boundaries), dtype=samples.dtype))
    return [float((idx == k).float().mean()) for k in range(len(boundaries) + 1)]
