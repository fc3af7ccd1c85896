"""Environments: PushT (pymunk, 2-D pushing) and the ALOHA-style arm pair (MuJoCo).

Classes load lazily so that PushT never imports mujoco and the arm pair never imports pymunk.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "PushTEnv": "coursekit.envs.pusht",
    "AlohaTransferCubeEnv": "coursekit.envs.aloha",
    "AlohaInsertionEnv": "coursekit.envs.aloha",
}
__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'coursekit.envs' has no attribute {name!r}")
    return getattr(importlib.import_module(_LAZY[name]), name)
