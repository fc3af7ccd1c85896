"""Fixtures shared by test modules (opt in with ``pytestmark = pytest.mark.usefixtures(...)``)."""

from __future__ import annotations

import os
import warnings

import pytest

# MuJoCo picks its OpenGL backend once, when first imported. A test module that runs
# `pytest.importorskip("mujoco")` before anything imports coursekit.envs.aloha (which sets this
# default itself) would otherwise lock in GLFW, which needs a display, and every later offscreen
# render fails. Same default as coursekit.envs.aloha and .ci/run, so plain `make test` works too.
os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture
def one_torch_thread():
    """Small ops: one thread is as fast, and immune to oversubscription on a shared CPU."""
    torch = pytest.importorskip("torch")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def chromium(request):
    """Path of Debian's headless chromium; without it the requesting module's browser tests skip, loudly."""
    from headless_chromium import find_chromium

    path = find_chromium()
    if path is None:
        reason = (f"!!! HEADLESS CHROMIUM IS NOT INSTALLED: the real-browser tests of {request.module.__name__} are "
                  "SKIPPED. Install it with `apt-get install -y chromium` (`make test` does this as root). !!!")
        warnings.warn(reason, stacklevel=1)
        pytest.skip(reason)
    return path
