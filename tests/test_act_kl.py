"""The closed-form CVAE KL against torch.distributions (the trusted reference)."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")
from torch.distributions import Independent, Normal, kl_divergence  # noqa: E402

from coursekit.nn.kl import gaussian_kl, gaussian_kl_per_dim  # noqa: E402


def _reference(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    q = Independent(Normal(mu, (0.5 * logvar).exp()), 1)
    p = Independent(Normal(torch.zeros_like(mu), torch.ones_like(mu)), 1)
    return kl_divergence(q, p).mean()  # sum over latent dims (Independent), mean over batch


@pytest.mark.parametrize("shape", [(1, 1), (8, 32), (5, 3)])
def test_matches_torch_distributions(shape):
    g = torch.Generator().manual_seed(sum(shape))
    mu = torch.randn(shape, generator=g, dtype=torch.float64) * 2
    logvar = torch.randn(shape, generator=g, dtype=torch.float64)
    assert torch.allclose(gaussian_kl(mu, logvar), _reference(mu, logvar), atol=1e-6, rtol=0)


def test_per_dim_sums_to_total_and_prior_is_zero():
    g = torch.Generator().manual_seed(0)
    mu, logvar = torch.randn(6, 4, generator=g), torch.randn(6, 4, generator=g)
    assert torch.allclose(gaussian_kl_per_dim(mu, logvar).sum(), gaussian_kl(mu, logvar), atol=1e-6)
    assert gaussian_kl(torch.zeros(3, 4), torch.zeros(3, 4)).item() == 0.0


def test_gradient_matches_reference():
    g = torch.Generator().manual_seed(1)
    mu = torch.randn(4, 5, generator=g, dtype=torch.float64, requires_grad=True)
    logvar = torch.randn(4, 5, generator=g, dtype=torch.float64, requires_grad=True)
    ours = torch.autograd.grad(gaussian_kl(mu, logvar), (mu, logvar))
    ref = torch.autograd.grad(_reference(mu, logvar), (mu, logvar))
    for a, b in zip(ours, ref):
        assert torch.allclose(a, b, atol=1e-9)


def test_shape_mismatch_is_rejected():
    with pytest.raises(ValueError, match="one shape"):
        gaussian_kl(torch.zeros(2, 3), torch.zeros(2, 4))
