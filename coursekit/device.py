"""Pick a torch device: an argument with auto-detection, never a hard-coded ``.cuda()``."""

from __future__ import annotations

from typing import Any


def resolve_device(device: Any = "auto") -> Any:
    """Return a ``torch.device``: ``"auto"`` picks cuda, then mps, then cpu.

    Accepts a string (``"cpu"``, ``"cuda:0"``, ``"auto"``) or a ``torch.device``. A device that is
    asked for but not available raises ``ValueError`` naming it.
    """
    import torch

    if isinstance(device, torch.device):
        return device
    if not isinstance(device, str):
        raise ValueError(f"device must be a string or torch.device, got {device!r}")
    if device == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda")
        if getattr(torch.backends, "mps", None) is not None and torch.backends.mps.is_available():
            return torch.device("mps")
        return torch.device("cpu")
    try:
        dev = torch.device(device)
    except RuntimeError:
        raise ValueError(f"unknown device {device!r}; expected auto, cpu, cuda, cuda:N or mps") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {device!r} was asked for but CUDA is not available; use 'auto' or 'cpu'")
    if dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"device {device!r} was asked for but MPS is not available; use 'auto' or 'cpu'")
    return dev
