"""Camera frames as the image policies take them, checked: (N, 3, H, W) uint8, 0..255.

Frames reach a policy from two places: a data set's ``image`` array (training) and the
environment's ``image`` observation (evaluation). Both arrive in one of the two layouts people
use, channels last (N, H, W, 3: what a renderer, PIL or LeRobot gives) or channels first
(N, 3, H, W: what torch convolutions take), as uint8 0..255 or as float in [0, 1]. Anything else
is a mistake that would train or run silently on garbage (a float frame in 0..255 read as
[0, 1] saturates to white; 64x64 frames against an encoder built for 96x96 fail deep inside
a convolution), so it is refused here with one line that names what came and what is expected.
"""

from __future__ import annotations

import math

import numpy as np

EXPECTED = "(N, H, W, 3) or (N, 3, H, W), uint8 0..255 or float in [0, 1]"


def frames_chw(images, size: tuple[int, int], name: str = "images") -> np.ndarray:
    """Frames (N, H, W, 3) or (N, 3, H, W), uint8 or float in [0, 1] -> (N, 3, H, W) uint8.

    ``size``: the (H, W) the encoder expects (``VisionEncoderConfig.input_size``). Raises a
    ValueError naming ``name``, the shape or dtype or value range that came, and what is expected.
    """
    a = np.asarray(images)
    if a.ndim != 4 or 3 not in (a.shape[1], a.shape[3]):
        raise ValueError(f"{name} must be frames {EXPECTED}; got shape {a.shape}")
    if a.shape[3] == 3 and a.shape[1] != 3:
        a = a.transpose(0, 3, 1, 2)  # (N, H, W, 3) -> (N, 3, H, W)
    if tuple(a.shape[2:]) != tuple(size):
        raise ValueError(f"{name} are {a.shape[2]}x{a.shape[3]} frames; this policy's encoder expects "
                         f"{size[0]}x{size[1]} (VisionEncoderConfig.frame_size): render or resize them to that")
    check_values(a, name)
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    return np.ascontiguousarray(np.rint(a * 255.0).astype(np.uint8))


def check_values(images, name: str = "images") -> None:
    """Raise a ValueError unless ``images`` (a numpy array or a torch tensor, any shape) are uint8,
    or float within [0, 1]; the message names ``name`` and the dtype or value range that came.

    One check for both ends: the data set's frames at training (via :func:`frames_chw`) and the
    raw observation a policy is handed (``UNetChunkPolicy``), which may already sit on a device.
    """
    kind = str(images.dtype).removeprefix("torch.")
    if kind == "uint8":
        return
    if not kind.startswith(("float", "bfloat")):
        raise ValueError(f"{name} must be uint8 0..255 or float in [0, 1]; got dtype {kind}")
    if math.prod(images.shape) == 0:
        return
    lo, hi = float(images.min()), float(images.max())  # NaN propagates through min and max
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"{name} contain NaN or inf (float frames must lie in [0, 1])")
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"float {name} must lie in [0, 1]; got values in [{lo:g}, {hi:g}] "
                         f"(0..255 frames: pass them as uint8)")
