"""The KL term of ACT's CVAE loss: a diagonal Gaussian posterior against the N(0, I) prior.

ACT (Zhao et al. 2023, Sec. IV-B, Eq. 1) trains its style variable z like a beta-VAE: the
encoder outputs q(z | a_{t:t+k}, o_t) = N(mu, diag(sigma^2)) and the loss adds

    beta * KL( N(mu, diag sigma^2) || N(0, I) )

For one sample with latent dimension d the KL has a closed form (Kingma & Welling 2014, App. B)::

    KL = 1/2 * sum_{j=1..d} ( mu_j^2 + sigma_j^2 - log sigma_j^2 - 1 )

The encoder predicts ``logvar = log sigma^2`` (not sigma) so that sigma^2 = exp(logvar) is
positive without a constraint. As in the original code, the KL is SUMMED over the latent
dimensions and AVERAGED over the batch.
"""

from __future__ import annotations

import torch


def gaussian_kl(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL( N(mu, diag(exp(logvar))) || N(0, I) ), summed over latent dims, averaged over the batch.

    Args:
        mu: (B, d) posterior means.
        logvar: (B, d) posterior log-variances, log sigma^2.

    Returns:
        kl: () scalar tensor, (1/B) * sum_b 1/2 * sum_j (mu_bj^2 + exp(logvar_bj) - logvar_bj - 1).

    Keep it differentiable (torch operations only): ACT back-propagates beta * kl into the encoder.
    """
    if mu.shape != logvar.shape or mu.dim() != 2:
        raise ValueError(f"gaussian_kl expects mu and logvar of one shape (B, d), got {tuple(mu.shape)} and {tuple(logvar.shape)}")
    # BEGIN SOLUTION
    per_dim = 0.5 * (mu.pow(2) + logvar.exp() - logvar - 1.0)  # (B, d)
    kl = per_dim.sum(dim=1).mean()
    # END SOLUTION
    return kl


def gaussian_kl_per_dim(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL of each latent dimension, averaged over the batch: (d,). Sums to ``gaussian_kl``.

    Used to see which latent dimensions the model actually uses: a dimension whose KL is near
    zero carries no information about the action chunk ("posterior collapse" for that dim).
    """
    if mu.shape != logvar.shape or mu.dim() != 2:
        raise ValueError(f"gaussian_kl_per_dim expects mu and logvar of one shape (B, d), got {tuple(mu.shape)} and {tuple(logvar.shape)}")
    return (0.5 * (mu.pow(2) + logvar.exp() - logvar - 1.0)).mean(dim=0)  # (d,)
