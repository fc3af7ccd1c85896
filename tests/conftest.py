"""Fixtures shared by test modules (opt in with ``pytestmark = pytest.mark.usefixtures(...)``)."""

from __future__ import annotations

import pytest


@pytest.fixture
def one_torch_thread():
    """Small ops: one thread is as fast, and immune to oversubscription on a shared CPU."""
    torch = pytest.importorskip("torch")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
