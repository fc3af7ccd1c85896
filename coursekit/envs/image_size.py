"""Image sizes given as an int (square) or a pair (H, W): one parser for every renderer and env."""

from __future__ import annotations

from typing import Any

import numpy as np


def size_hw(size: Any, name: str = "size") -> tuple[int, int]:
    """``size`` (int or (H, W) of positive ints) -> (H, W); anything else -> ValueError naming ``name``."""
    if isinstance(size, (int, np.integer)):
        hw: tuple[Any, ...] = (size, size)
    else:
        try:
            hw = tuple(size)
        except TypeError:
            hw = ()
    if len(hw) != 2 or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v > 0 for v in hw):
        raise ValueError(f"{name} must be a positive int or a pair (H, W) of positive ints, got {size!r}")
    return int(hw[0]), int(hw[1])
