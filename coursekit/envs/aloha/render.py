"""Offscreen camera images of a MuJoCo scene on the CPU, fast enough to render datasets.

MuJoCo's OpenGL renderer runs headless through EGL (Mesa's llvmpipe on a CPU-only machine) or
OSMesa; ``MUJOCO_GL`` must be set before ``mujoco`` is imported (coursekit.envs.aloha.model does
``os.environ.setdefault("MUJOCO_GL", "egl")``). Shadows and reflections dominate the CPU cost
(a 240x320 frame: about 50 ms with them, about 5 ms without), so both are switched off.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np


class CameraRenderer:
    """Renders (H, W, 3) uint8 images from named cameras of one model.

    Args:
        model: the compiled model (its ``<visual><global offwidth/offheight>`` bound the size).
        height, width: image size in pixels.
    """

    def __init__(self, model: mujoco.MjModel, height: int, width: int) -> None:
        if height < 1 or width < 1:
            raise ValueError(f"image size must be positive, got height={height}, width={width}")
        max_w, max_h = model.vis.global_.offwidth, model.vis.global_.offheight
        if width > max_w or height > max_h:
            raise ValueError(f"image size {height}x{width} exceeds the model's offscreen buffer {max_h}x{max_w}")
        self.model = model
        self.height, self.width = height, width
        try:
            self._renderer = mujoco.Renderer(model, height=height, width=width)
        except mujoco.FatalError as exc:
            raise RuntimeError(
                f"MuJoCo could not create an offscreen OpenGL context (MUJOCO_GL is now "
                f"{os.environ.get('MUJOCO_GL')!r}, but mujoco reads it when first imported): set "
                "MUJOCO_GL=egl (or osmesa) before mujoco is first imported, e.g. import coursekit.envs.aloha "
                "before mujoco"
            ) from exc
        self._cameras = {model.camera(i).name for i in range(model.ncam)}

    def render(self, data: mujoco.MjData, camera: str = "top") -> np.ndarray:
        """(H, W, 3) uint8 image of ``data`` (its kinematics must be current) from ``camera``."""
        if camera not in self._cameras:
            raise ValueError(f"unknown camera {camera!r}; the model has {sorted(self._cameras)}")
        self._renderer.update_scene(data, camera=camera)
        flags = self._renderer.scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        return self._renderer.render()  # (H, W, 3) uint8

    def close(self) -> None:
        self._renderer.close()
