"""Checkpoints: round trip with identical predictions; every kind of corrupt/mismatched checkpoint refused."""

from __future__ import annotations

import json
import os
import pickle
import re

import numpy as np
import pytest
import torch

from coursekit.checkpoint import CheckpointError, load_checkpoint, read_checkpoint_info, save_checkpoint
from coursekit.weights_file import config_digest, file_sha256
from coursekit.data import MinMaxNormalizer
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
from coursekit.policies.regression import RegressionPolicy, RegressionPolicyConfig

TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)
NORMS = {"obs": MinMaxNormalizer(np.arange(6.0), np.arange(6.0) + 400),
         "action": MinMaxNormalizer(np.full(2, 20.0), np.full(2, 480.0))}


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


@pytest.fixture
def saved(tmp_path):
    torch.manual_seed(0)
    policy = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, n_action_steps=6), NORMS)
    path = save_checkpoint(policy, tmp_path / "ckpt", dataset_meta={"seed": 0, "n_episodes": 3},
                           training={"steps": 7})
    return policy, path


def test_round_trip_gives_identical_predictions(saved):
    policy, path = saved
    loaded = load_checkpoint(path, device="cpu")
    assert isinstance(loaded, DiffusionPolicy) and loaded.config == policy.config
    obs = torch.rand(3, 2, 6) * 400
    a = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(1))
    b = loaded.predict_chunk(obs, generator=torch.Generator().manual_seed(1))
    assert torch.equal(a, b)
    np.testing.assert_array_equal(loaded.normalizers["action"].low, NORMS["action"].low)
    info = read_checkpoint_info(path)
    assert info["policy_type"] == "diffusion" and info["training"]["steps"] == 7
    assert info["dataset"]["n_episodes"] == 3 and info["weights"]["sha256"] == file_sha256(path / "model.safetensors")
    assert sorted(p.name for p in path.iterdir()) == ["config.json", "model.safetensors"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o777 & ~umask  # ordinary modes, not mkdtemp's private ones
    assert all(p.stat().st_mode & 0o777 == 0o666 & ~umask for p in path.iterdir())


def test_overwrite_is_atomic_and_leaves_no_temporary_files(saved, tmp_path):
    policy, path = saved
    with torch.no_grad():
        next(policy.parameters()).add_(1.0)
    save_checkpoint(policy, path)
    loaded = load_checkpoint(path, device="cpu")
    assert torch.equal(next(loaded.parameters()), next(policy.parameters()))
    assert [p.name for p in tmp_path.iterdir()] == ["ckpt"]


def test_regression_round_trip(tmp_path):
    policy = RegressionPolicy(RegressionPolicyConfig(unet=TINY), NORMS)
    loaded = load_checkpoint(save_checkpoint(policy, tmp_path / "r"), device="cpu", expected_type="regression")
    obs = np.random.default_rng(0).uniform(0, 400, (2, 2, 6)).astype(np.float32)
    np.testing.assert_array_equal(policy.predict_chunk(obs), loaded.predict_chunk(obs))


def test_half_precision_storage_loads_into_float32(saved, tmp_path):
    policy, path = saved
    half = save_checkpoint(policy, tmp_path / "half", half=True)
    assert (half / "model.safetensors").stat().st_size < 0.6 * (path / "model.safetensors").stat().st_size
    loaded = load_checkpoint(half, device="cpu")
    assert all(p.dtype == torch.float32 for p in loaded.parameters())
    assert read_checkpoint_info(half)["weights"]["dtype"] == "float16"
    for (name, a), b in zip(policy.state_dict().items(), loaded.state_dict().values()):
        torch.testing.assert_close(b, a.half().float(), msg=name)


def _edit_config(path, fn):
    """Edit config.json as a deliberate, consistent edit would (re-binding the config digest)."""
    info = json.loads((path / "config.json").read_text())
    fn(info)
    if {"policy_type", "config", "normalizers"} <= set(info) and isinstance(info.get("weights"), dict):
        info["weights"]["config_sha256"] = config_digest(info)
    (path / "config.json").write_text(json.dumps(info))


def test_refuses_truncated_weights(saved):
    _, path = saved
    w = path / "model.safetensors"
    w.write_bytes(w.read_bytes()[:-100])
    with pytest.raises(CheckpointError, match="sha256"):
        load_checkpoint(path, device="cpu")
    _edit_config(path, lambda i: i["weights"].update(sha256=file_sha256(w)))  # even with a matching hash
    with pytest.raises(CheckpointError, match="safetensors"):
        load_checkpoint(path, device="cpu")


def test_never_unpickles(saved):
    policy, path = saved
    w = path / "model.safetensors"
    w.write_bytes(pickle.dumps(policy.state_dict()))
    _edit_config(path, lambda i: i["weights"].update(sha256=file_sha256(w)))
    with pytest.raises(CheckpointError, match="safetensors"):
        load_checkpoint(path, device="cpu")


def _as_older_checkpoint(path):
    """Rewrite the weights as coursekit wrote them before the config digest went into their metadata
    (same tensors, metadata {format, policy_type} only), like the shipped checkpoints."""
    from safetensors.torch import load_file, save_file

    w = path / "model.safetensors"
    save_file(load_file(str(w)), str(w), metadata={"format": "coursekit-checkpoint", "policy_type": "diffusion"})
    _edit_config(path, lambda i: i["weights"].update(sha256=file_sha256(w)))


def test_a_consistent_edit_of_config_json_is_refused_by_the_weights_metadata(saved):
    _, path = saved
    _edit_config(path, lambda i: i["config"].update(horizon=32))  # digest in config.json re-bound, weights' not
    with pytest.raises(CheckpointError, match="was saved with another policy_type/config/normalizers"):
        load_checkpoint(path, device="cpu")


def test_refuses_shape_mismatch(saved):
    _, path = saved
    _as_older_checkpoint(path)
    assert torch.equal(next(iter(load_checkpoint(path, device="cpu").state_dict().values())),
                       next(iter(saved[0].state_dict().values())))  # an older checkpoint still loads
    _edit_config(path, lambda i: i["config"]["unet"].update(down_dims=[16, 64]))
    with pytest.raises(CheckpointError, match="has shape"):
        load_checkpoint(path, device="cpu")


def test_refuses_wrong_or_unknown_policy_type(saved):
    _, path = saved
    with pytest.raises(CheckpointError, match="expected 'regression'"):
        load_checkpoint(path, device="cpu", expected_type="regression")
    _edit_config(path, lambda i: i.update(policy_type="transformer"))
    with pytest.raises(CheckpointError, match="unknown policy type"):
        load_checkpoint(path, device="cpu")


def test_refuses_config_with_unknown_field_or_bad_value(saved):
    _, path = saved
    _edit_config(path, lambda i: i["config"].update(flux_capacitor=1))
    with pytest.raises(CheckpointError, match="flux_capacitor"):
        load_checkpoint(path, device="cpu")
    _edit_config(path, lambda i: (i["config"].pop("flux_capacitor"), i["config"].update(n_action_steps=40)))
    with pytest.raises(CheckpointError, match="n_action_steps=40"):
        load_checkpoint(path, device="cpu")


def test_refuses_missing_files_and_bad_json(saved, tmp_path):
    _, path = saved
    with pytest.raises(FileNotFoundError, match="not found"):
        load_checkpoint(tmp_path / "nothing")
    (path / "config.json").write_text("{not json")
    with pytest.raises(CheckpointError, match="JSON"):
        load_checkpoint(path)
    (path / "config.json").unlink()
    with pytest.raises(FileNotFoundError, match="config.json"):
        load_checkpoint(path)


def test_refuses_missing_weights_and_foreign_json(saved):
    _, path = saved
    (path / "model.safetensors").unlink()
    with pytest.raises(FileNotFoundError, match="weights"):
        load_checkpoint(path)
    (path / "config.json").write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(CheckpointError, match="not a coursekit checkpoint"):
        load_checkpoint(path)


def test_copy_checkpoint_half_keeps_provenance(saved, tmp_path):
    policy, path = saved
    from coursekit.checkpoint import copy_checkpoint_half

    dest = copy_checkpoint_half(path, tmp_path / "shipped")
    src_info, info = read_checkpoint_info(path), read_checkpoint_info(dest)
    assert info["weights"]["dtype"] == "float16"
    assert (info["dataset"], info["training"], info["config"]) == (src_info["dataset"], src_info["training"], src_info["config"])
    for (name, a), b in zip(policy.state_dict().items(), load_checkpoint(dest, device="cpu").state_dict().values()):
        torch.testing.assert_close(b, a.half().float(), msg=name)


def test_training_budget_sums_the_init_from_chain(tmp_path):
    from coursekit.checkpoint import training_budget

    info = {"training": {"steps": 10749, "seconds": 2400.0, "init_from": {"steps": 8510, "seconds": 1200.0, "init_from": None}}}
    assert training_budget(info) == {"steps": 19259, "seconds": 3600.0, "minutes": 60.0, "segments": 2}
    assert training_budget({"training": {"steps": 5, "init_from": {"steps": 3}}})["seconds"] is None
    assert training_budget({}) == {"steps": None, "seconds": None, "minutes": None, "segments": 0}
    with pytest.raises(FileNotFoundError):
        training_budget(tmp_path / "missing")


def test_resaving_keeps_the_run_folders_other_files(saved):
    """A training run re-saves its checkpoint into a folder that also holds metrics.csv: nothing else is lost,
    and a writer holding the CSV open keeps writing into the new folder (the file is carried over, not copied)."""
    policy, path = saved
    (path / "notes.txt").write_text("mine")
    with open(path / "metrics.csv", "w") as fh:
        fh.write("step\n1\n")
        fh.flush()
        save_checkpoint(policy, path, training={"steps": 8})
        fh.write("2\n")
    assert (path / "notes.txt").read_text() == "mine"
    assert (path / "metrics.csv").read_text() == "step\n1\n2\n"
    assert read_checkpoint_info(path)["training"]["steps"] == 8
    assert sorted(p.name for p in path.parent.iterdir()) == ["ckpt"]  # no temporary folder left behind


def test_find_checkpoint_looks_in_the_shipped_folder_then_elsewhere(saved, tmp_path):
    from coursekit.checkpoint import SHIPPED_DIR, find_checkpoint, shipped_checkpoints

    _, path = saved
    assert find_checkpoint("pusht_diffusion_state") == SHIPPED_DIR / "pusht_diffusion_state"
    assert "act_transfer_cube" in shipped_checkpoints()
    assert find_checkpoint("no_such_checkpoint") is None
    assert find_checkpoint("no_such_checkpoint", "ckpt", also_in=(path.parent,)) == path


def test_the_documented_layout_names_every_registered_policy_type():
    import coursekit.checkpoint
    from coursekit.policies import POLICY_TYPES

    layout = next(line for line in coursekit.checkpoint.__doc__.splitlines() if '"policy_type":' in line)
    assert sorted(re.findall(r'"(\w+)"', layout.split(":", 1)[1])) == sorted(POLICY_TYPES)
