"""Environments: PushT (pymunk, 2-D pushing) and the ALOHA-style arm pair (MuJoCo).

Classes load lazily so that PushT never imports mujoco and the arm pair never imports pymunk.
"""

from __future__ import annotations

from coursekit.lazy import lazy_loader

_LAZY = {
    "PushTEnv": "coursekit.envs.pusht",
    "AlohaTransferCubeEnv": "coursekit.envs.aloha",
    "AlohaInsertionEnv": "coursekit.envs.aloha",
}
__all__ = sorted(_LAZY)
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)
