"""The ALOHA-style arm pair in MuJoCo: two ViperX-300-s-style arms, two ACT tasks.

Importing this package sets ``MUJOCO_GL=egl`` (unless already set) before MuJoCo loads, so
camera images render offscreen on a CPU-only machine.

    AlohaTransferCubeEnv  coursekit/AlohaTransferCube-v0
    AlohaInsertionEnv     coursekit/AlohaInsertion-v0
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before any `import mujoco`

from coursekit.envs.aloha.env import AlohaEnv, AlohaInsertionEnv, AlohaTransferCubeEnv  # noqa: E402
from coursekit.envs.aloha.model import STATE_NAMES, load_model  # noqa: E402

__all__ = ["AlohaEnv", "AlohaInsertionEnv", "AlohaTransferCubeEnv", "STATE_NAMES", "load_model"]
