"""benchmarks/resumable.py: a finished run is loaded, never rebuilt or retrained; run folders are named stably."""

from __future__ import annotations

import pytest
import torch

from benchmarks.resumable import is_trained, load_or_train, run_slug, state_path
from coursekit.policies.factory import make_policy
from test_train import TINY, synthetic_pusht

pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


def _weights(policy) -> torch.Tensor:
    return torch.cat([p.detach().flatten() for p in policy.parameters()])


def test_run_slug_is_the_folder_name_the_runs_in_progress_use():
    assert run_slug("Diffusion Policy DDIM-10 (To=2, Tp=16, Ta=8)") == "diffusion-policy-ddim-10-to-2-tp-16-ta-8"
    assert run_slug("ACT k=100 without CVAE") == "act-k-100-without-cvae"


def test_a_finished_run_is_loaded_without_building_anything(tmp_path):
    calls = []

    def build():
        calls.append(1)
        policy, batches, recipe = make_policy("diffusion", synthetic_pusht(), batch_size=8, seed=0, unet=TINY)
        return policy, batches, {**recipe, "warmup_steps": 1, "log_every": 1}

    run = tmp_path / "runs" / "tiny_seed0_s3"
    trained = load_or_train(run, build, steps=3, seed=0)
    assert calls == [1] and is_trained(run) and not state_path(run).exists()

    def must_not_build():
        raise AssertionError("a finished run was rebuilt")

    loaded = load_or_train(run, must_not_build, steps=3, seed=0)
    assert torch.allclose(_weights(loaded), _weights(trained))  # the EMA weights the checkpoint holds
