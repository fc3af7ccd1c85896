"""Argument checks shared by the environments: one clear ValueError per bad reset seed, option or array.

Gymnasium leaves these to each environment; without them a string ``options`` fails deep inside
with an AttributeError, a misspelt option key is silently ignored, and a non-numeric action
surfaces as numpy's "could not convert string to float".
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

MAX_SEED = 2**32 - 1
"""Largest seed numpy's legacy RandomState (PushT's reference draw) accepts."""


def check_reset_args(seed: Any, options: Any, known_options: Mapping[str, str], env: str) -> dict[str, Any]:
    """Validate ``reset(seed=, options=)``; returns the options as a dict ({} for None).

    ``known_options`` maps each accepted key to a one-line description (shown when a key is unknown).
    """
    if seed is not None and (not isinstance(seed, (int, np.integer)) or isinstance(seed, bool)
                             or not 0 <= int(seed) <= MAX_SEED):
        raise ValueError(f"{env}.reset: seed must be None or an int in [0, 2**32 - 1], got {seed!r}")
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ValueError(f"{env}.reset: options must be None or a dict, got {options!r} ({type(options).__name__})")
    unknown = sorted(str(k) for k in options if k not in known_options)
    if unknown:
        known = "; ".join(f"{k!r}: {v}" for k, v in known_options.items())
        raise ValueError(f"{env}.reset: unknown option(s) {unknown}; known options: {known}")
    return dict(options)


def finite_array(value: Any, shape: tuple[int, ...], name: str, layout: str = "") -> np.ndarray:
    """``value`` as a float64 array of exactly ``shape`` with finite entries, or a ValueError naming it."""
    layout = f" {layout}" if layout else ""
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":  # numpy would turn "0" into 0.0 and True into 1.0: not numbers here
            raise TypeError
        a = raw.astype(np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric with shape {shape}{layout}, got {value!r}") from None
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}{layout}, got shape {a.shape}: {value!r}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (no NaN or inf), got {a.tolist()!r}")
    return a
