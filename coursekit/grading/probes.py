"""Tiny torch modules the graded tests build INSIDE the worker (``sandbox.new``) as stand-ins for a
network, when a test needs gradients to flow through the student's code into parameters."""

from __future__ import annotations

import torch
from torch import nn


class Scale(nn.Module):
    """A model (x_t, t, cond) -> w * x_t (noise or velocity prediction): one scalar parameter ``w``."""

    def __init__(self, w: float) -> None:
        super().__init__()
        self.w = nn.Parameter(torch.tensor(float(w)))

    def forward(self, x: torch.Tensor, t=None, cond=None) -> torch.Tensor:
        return self.w * x
