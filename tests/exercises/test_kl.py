"""Exercise 7.1 (kl): the closed-form KL of a diagonal Gaussian to N(0, I), ACT's CVAE regulariser.

Reference: torch.distributions.kl_divergence on Independent(Normal) distributions (summed over
the latent dimensions, averaged over the batch), on seeded inputs.
"""

from __future__ import annotations

import pytest
import torch
from torch.distributions import Independent, Normal, kl_divergence

EXERCISE = "kl"


def reference(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    q = Independent(Normal(mu, (0.5 * logvar).exp()), 1)
    p = Independent(Normal(torch.zeros_like(mu), torch.ones_like(mu)), 1)
    return kl_divergence(q, p).mean()


def _inputs(seed: int, shape=(8, 32), dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(shape, generator=g, dtype=dtype) * 2, torch.randn(shape, generator=g, dtype=dtype)


def test_returns_a_scalar(student):
    mu, logvar = _inputs(0, dtype=torch.float32)
    got = student.gaussian_kl(mu, logvar)
    assert torch.is_tensor(got), f"expected a torch tensor, got {type(got).__name__}"
    assert got.shape == (), f"expected a scalar (shape ()), got shape {tuple(got.shape)}: average over the batch"
    assert torch.isfinite(got), "KL is not finite"


def test_zero_at_the_prior(student):
    got = student.gaussian_kl(torch.zeros(4, 3), torch.zeros(4, 3))
    assert abs(float(got)) < 1e-7, f"KL(N(0, I) || N(0, I)) must be 0, got {float(got)}"


@pytest.mark.parametrize("seed", range(3))
def test_matches_torch_distributions(student, seed):
    mu, logvar = _inputs(seed, shape=(5 + seed, 3 + 7 * seed))
    got, want = student.gaussian_kl(mu, logvar), reference(mu, logvar)
    assert abs(float(got) - float(want)) < 1e-6, f"got {float(got):.6f}, torch.distributions says {float(want):.6f}"


def test_sum_over_latent_mean_over_batch(student):
    mu, logvar = _inputs(3, shape=(1, 4))
    one = float(student.gaussian_kl(mu, logvar))
    # four copies of the same sample: the batch MEAN is unchanged
    assert abs(float(student.gaussian_kl(mu.repeat(4, 1), logvar.repeat(4, 1))) - one) < 1e-9, \
        "the KL must be averaged (not summed) over the batch"
    # the same sample with its latent dims repeated twice: the SUM over dims doubles
    assert abs(float(student.gaussian_kl(mu.repeat(1, 2), logvar.repeat(1, 2))) - 2 * one) < 1e-9, \
        "the KL must be summed (not averaged) over the latent dimensions"


def test_gradients_match(student, sandbox):
    mu, logvar = _inputs(4, shape=(3, 5))
    value, (g_mu, g_logvar) = sandbox.grad(student.gaussian_kl, mu, logvar, wrt=(0, 1))  # computed in the worker
    mu_ref, logvar_ref = mu.clone().requires_grad_(True), logvar.clone().requires_grad_(True)
    want = torch.autograd.grad(reference(mu_ref, logvar_ref), (mu_ref, logvar_ref))
    for name, got, ref in (("mu", g_mu, want[0]), ("logvar", g_logvar, want[1])):
        assert got is not None, f"no gradient reached {name}: compute the KL with torch operations (no .item(), no numpy)"
        assert tuple(got.shape) == tuple(ref.shape), f"d KL / d {name} has shape {tuple(got.shape)}, expected {tuple(ref.shape)}"
        assert torch.allclose(got, ref, atol=1e-8), (
            f"d KL / d {name} differs from torch.distributions' (max error {float((got - ref).abs().max()):.3g})")
