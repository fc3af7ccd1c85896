"""A fast PushT rasteriser (PIL): images for pixel observations and ``render()``.

The reference draws the 512 x 512 scene with pygame and resizes it to 96 x 96 (an area
average). We draw directly at ``supersample`` times the target size with PIL and box-average
down (``Image.reduce``), which gives the same soft edges at a fraction of the cost and needs no
pygame or OpenCV.

Colours are the reference's (CSS names): white background, light green goal T, light slate grey
block with a darker 2-unit outline (centred on the edges, as PIL draws it), royal blue
pusher, light grey walls. The action target is never
drawn into observations; ``render(..., target=...)`` marks it with a small cross for viewing.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from coursekit.envs import pusht_geometry as geo
from coursekit.envs.image_size import size_hw

WHITE = (255, 255, 255)
"""Background."""
GOAL_COLOR = (144, 238, 144)
"""CSS LightGreen: the goal T."""
BLOCK_COLOR = (119, 136, 153)
"""CSS LightSlateGray: the block's fill."""
BLOCK_OUTLINE = (72, 84, 96)
"""A darker slate grey: the block's outline."""
AGENT_COLOR = (65, 105, 225)
"""CSS RoyalBlue: the pusher."""
WALL_COLOR = (211, 211, 211)
"""CSS LightGray: the walls."""
TARGET_COLOR = (220, 20, 60)
"""CSS Crimson: the action-target cross (render() only, never in observations)."""


class PushTRenderer:
    """Renders PushT states to (H, W, 3) uint8 images; the static part (walls, goal) is drawn once.

    Args:
        size: output size, int or (H, W).
        supersample: drawing resolution factor before box-averaging down; default chooses
            4 for small images (<= 128 px), 2 up to 256 px, else 1.
    """

    def __init__(self, size=96, supersample: int | None = None):
        self.height, self.width = size_hw(size)
        if supersample is None:
            longest = max(self.height, self.width)
            supersample = 4 if longest <= 128 else 2 if longest <= 256 else 1
        if not isinstance(supersample, (int, np.integer)) or supersample < 1:
            raise ValueError(f"supersample must be a positive int, got {supersample!r}")
        self.supersample = int(supersample)
        ss = self.supersample
        self._canvas = (self.width * ss, self.height * ss)  # PIL size is (W, H)
        self._scale = np.array([self.width * ss / geo.WORLD_SIZE, self.height * ss / geo.WORLD_SIZE])
        self._unit = float(self._scale.mean())  # canvas pixels per world unit

        background = Image.new("RGB", self._canvas, WHITE)
        draw = ImageDraw.Draw(background)
        lo, hi = geo.WALL_LO, geo.WALL_HI
        corners = self._px(np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi], [lo, lo]]))
        draw.line(corners, fill=WALL_COLOR, width=max(1, round(2 * geo.WALL_RADIUS * self._unit)))
        draw.polygon(self._px(geo.block_outline(geo.GOAL_POSE)), fill=GOAL_COLOR)
        self._background = background

    def _px(self, pts: np.ndarray) -> list[tuple[float, float]]:
        """World points (N, 2) -> canvas pixel coordinates as a list of (x, y) tuples."""
        return [tuple(p) for p in (np.asarray(pts) * self._scale).tolist()]

    def render(self, state, target=None) -> np.ndarray:
        """(H, W, 3) uint8 image of ``state`` = [ax, ay, bx, by, angle]; ``target`` (2,) optional."""
        s = geo.as_state5(state)
        img = self._background.copy()
        draw = ImageDraw.Draw(img)
        outline_w = max(1, round(2.0 * self._unit))
        draw.polygon(self._px(geo.block_outline(s[2:5])), fill=BLOCK_COLOR, outline=BLOCK_OUTLINE,
                     width=outline_w)
        cx, cy = (s[:2] * self._scale).tolist()
        rx, ry = (geo.AGENT_RADIUS * self._scale).tolist()
        draw.ellipse((cx - rx, cy - ry, cx + rx, cy + ry), fill=AGENT_COLOR)
        if target is not None:
            t = np.asarray(target, dtype=np.float64)
            if t.shape == (2,) and np.all(np.isfinite(t)):
                tx, ty = (t * self._scale).tolist()
                r = 8.0 * self._unit
                w = max(self.supersample, round(3.0 * self._unit))  # at least 1 output pixel
                draw.line((tx - r, ty - r, tx + r, ty + r), fill=TARGET_COLOR, width=w)
                draw.line((tx - r, ty + r, tx + r, ty - r), fill=TARGET_COLOR, width=w)
        if self.supersample > 1:
            img = img.reduce(self.supersample)
        return np.array(img, dtype=np.uint8)  # (H, W, 3)


def render_state(state, size=96, target=None) -> np.ndarray:
    """One-off render of ``state`` (5,) to an (H, W, 3) uint8 image (see ``PushTRenderer``)."""
    return PushTRenderer(size).render(state, target=target)
