"""Bad checkpoint configs are refused field by field; weights stay inside the checkpoint; bytes are reproducible.

Property-based (hypothesis): any single mutation of a valid config dict — a field dropped, an
unknown field added, a value replaced by one of another JSON type — is refused by
``config_from_dict`` with a message naming the field, while every valid dict round-trips exactly.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coursekit.checkpoint import CheckpointError, _sha256, load_checkpoint, save_checkpoint
from coursekit.config import config_from_dict, config_to_dict
from coursekit.data import MinMaxNormalizer
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.act import ACTConfig
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig

ROOT = Path(__file__).resolve().parent.parent
TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)
NORMS = {"obs": MinMaxNormalizer(np.arange(6.0), np.arange(6.0) + 400),
         "action": MinMaxNormalizer(np.full(2, 20.0), np.full(2, 480.0))}
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

pytestmark = pytest.mark.usefixtures("one_torch_thread")

CONFIGS = [DiffusionPolicyConfig(unet=TINY), ACTConfig(), ACTConfig(obs_type="image", obs_dim=2)]


def _paths(d: dict, prefix: tuple = ()) -> list[tuple]:
    """Every (nested) field path of a config dict."""
    out = []
    for k, v in d.items():
        out.append(prefix + (k,))
        if isinstance(v, dict):
            out += _paths(v, prefix + (k,))
    return out


def _wrong_type(value):
    """Values of a JSON type other than ``value``'s (a bool is not an int, "false" is not a bool)."""
    candidates = ["false", "7", 3, 2.5, True, False, [1, 2], {"a": 1}, None]
    if isinstance(value, bool):
        bad = [c for c in candidates if not isinstance(c, bool)]
    elif isinstance(value, int):
        bad = [c for c in candidates if isinstance(c, (bool, str, list, dict, float)) or c is None]
        bad = [c for c in bad if not (isinstance(c, float) and c.is_integer())]
    elif isinstance(value, float):
        bad = [c for c in candidates if isinstance(c, (bool, str, list, dict))]
    elif isinstance(value, str):
        bad = [c for c in candidates if not isinstance(c, str)]
    elif isinstance(value, list):
        bad = [c for c in candidates if not isinstance(c, list)] + [["x"] * len(value), [True] * len(value)]
    elif isinstance(value, dict):
        bad = [c for c in candidates if not isinstance(c, dict)]
    else:  # None of an optional field: a non-null of the wrong kind
        bad = ["false", [1, 2]]
    return bad


def _set(d: dict, path: tuple, value) -> None:
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value


def _drop(d: dict, path: tuple) -> None:
    for k in path[:-1]:
        d = d[k]
    del d[path[-1]]


@SETTINGS
@given(data=st.data())
def test_any_single_field_mutation_is_refused_naming_the_field(data):
    config = data.draw(st.sampled_from(CONFIGS))
    cls, good = type(config), config_to_dict(config)
    assert config_from_dict(cls, json.loads(json.dumps(good))) == config  # the unmutated dict round-trips
    path = data.draw(st.sampled_from(_paths(good)))
    bad = json.loads(json.dumps(good))
    kind = data.draw(st.sampled_from(["drop", "unknown", "type"]))
    if kind == "drop":
        _drop(bad, path)
        named = path[-1]
    elif kind == "unknown":
        named = data.draw(st.from_regex(r"[a-z]{3,12}_x", fullmatch=True))
        _set(bad, path[:-1] + (named,), 1)
    else:
        current = good
        for k in path:
            current = current[k]
        _set(bad, path, data.draw(st.sampled_from(_wrong_type(current))))
        named = path[-1]
    with pytest.raises(ValueError, match=named):
        config_from_dict(cls, bad)


@SETTINGS
@given(k=st.integers(1, 64), ta=st.one_of(st.none(), st.integers(1, 64)), use_vae=st.booleans(),
       kl=st.floats(0, 100, allow_nan=False), te=st.booleans())
def test_valid_act_configs_round_trip_exactly(k, ta, use_vae, kl, te):
    if ta is not None and ta > k:
        ta = k
    config = ACTConfig(chunk_size=k, n_action_steps=ta, use_vae=use_vae, kl_weight=kl, temporal_ensembling=te)
    again = config_from_dict(ACTConfig, json.loads(json.dumps(config_to_dict(config))))
    assert again == config and type(again.use_vae) is bool


def test_type_errors_name_the_field_the_value_and_the_type():
    good = config_to_dict(ACTConfig())
    with pytest.raises(ValueError, match=r"ACTConfig\.use_vae: expected bool, got 'false' \(str\)"):
        config_from_dict(ACTConfig, {**good, "use_vae": "false"})
    with pytest.raises(ValueError, match=r"ACTConfig\.chunk_size: expected int, got True"):
        config_from_dict(ACTConfig, {**good, "chunk_size": True})
    dp = config_to_dict(DiffusionPolicyConfig(unet=TINY))
    with pytest.raises(ValueError, match=r"unet\.down_dims\[1\]: expected int, got '32'"):
        config_from_dict(DiffusionPolicyConfig, {**dp, "unet": {**dp["unet"], "down_dims": [16, "32"]}})
    with pytest.raises(ValueError, match=r"missing field\(s\) \['horizon'\]"):
        config_from_dict(DiffusionPolicyConfig, {k: v for k, v in dp.items() if k != "horizon"})


@pytest.fixture
def saved(tmp_path):
    torch.manual_seed(0)
    policy = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, n_action_steps=6), NORMS)
    return policy, save_checkpoint(policy, tmp_path / "ckpt")


def _edit(path: Path, fn) -> None:
    """An edit by hand: config.json changes, the recorded digests do not."""
    info = json.loads((path / "config.json").read_text())
    fn(info)
    (path / "config.json").write_text(json.dumps(info))


def test_a_hand_edited_config_is_refused_even_if_the_weights_still_fit(saved):
    _, path = saved
    _edit(path, lambda i: i["config"].update(horizon=32))  # the U-Net's tensors do not depend on Tp
    with pytest.raises(CheckpointError, match="config_sha256"):
        load_checkpoint(path, device="cpu")


def test_a_string_bool_or_a_missing_field_is_refused_on_load(saved):
    _, path = saved
    _edit(path, lambda i: i["config"].update(clip_sample="false"))
    with pytest.raises(CheckpointError, match=r"clip_sample: expected bool, got 'false'"):
        load_checkpoint(path, device="cpu")
    _edit(path, lambda i: (i["config"].update(clip_sample=True), i["config"].pop("ddim_eta")))
    with pytest.raises(CheckpointError, match=r"missing field\(s\) \['ddim_eta'\]"):
        load_checkpoint(path, device="cpu")


@pytest.mark.parametrize("name", ["/etc/passwd", "../outside.safetensors", "sub/model.safetensors", "", "..", 7])
def test_weights_must_be_a_file_inside_the_checkpoint(saved, name):
    _, path = saved
    _edit(path, lambda i: i["weights"].update(file=name))
    with pytest.raises(CheckpointError, match=r"weights\.file must name a file inside the checkpoint"):
        load_checkpoint(path, device="cpu")


def test_a_symlinked_weights_file_is_refused(saved, tmp_path):
    _, path = saved
    outside = tmp_path / "outside.safetensors"
    os.replace(path / "model.safetensors", outside)
    (path / "model.safetensors").symlink_to(outside)
    with pytest.raises(FileNotFoundError, match="not a link"):
        load_checkpoint(path, device="cpu")


_SAVE = """
import sys, torch, numpy as np
from coursekit.checkpoint import save_checkpoint
from coursekit.data import MinMaxNormalizer
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
torch.manual_seed(0)
unet = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)
norms = {"obs": MinMaxNormalizer(np.arange(6.0), np.arange(6.0) + 400),
         "action": MinMaxNormalizer(np.full(2, 20.0), np.full(2, 480.0))}
policy = DiffusionPolicy(DiffusionPolicyConfig(unet=unet), norms)
for i in range(3):
    save_checkpoint(policy, sys.argv[1] + f"/ckpt{i}")
"""


def test_identical_policies_give_identical_weight_bytes_in_any_process(tmp_path):
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        subprocess.run([sys.executable, "-c", _SAVE, str(tmp_path / run)], check=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    files = sorted(tmp_path.glob("*/ckpt*/model.safetensors"))
    assert len(files) == 6
    assert len({hashlib.sha256(f.read_bytes()).hexdigest() for f in files}) == 1
    recorded = {json.loads((f.parent / "config.json").read_text())["weights"]["sha256"] for f in files}
    assert recorded == {_sha256(files[0])}
    raw = files[0].read_bytes()
    header = json.loads(raw[8:8 + int.from_bytes(raw[:8], "little")])
    assert list(header["__metadata__"]) == sorted(header["__metadata__"])
    from safetensors.torch import load_file  # still a valid safetensors file
    assert set(load_file(str(files[0]))) == set(DiffusionPolicy(DiffusionPolicyConfig(unet=TINY), NORMS).state_dict())


def test_every_shipped_checkpoint_loads_strictly_and_is_bound_to_its_config():
    shipped = sorted(p for p in (ROOT / "coursekit" / "checkpoints").iterdir() if (p / "config.json").is_file())
    assert shipped
    for path in shipped:
        info = json.loads((path / "config.json").read_text())
        policy = load_checkpoint(path, device="cpu")
        assert config_to_dict(policy.config) == info["config"], path.name  # every field given, none defaulted
        assert "config_sha256" in info["weights"], path.name


def test_saving_never_deletes_or_replaces_a_users_files(saved, tmp_path):
    policy, _ = saved
    results = tmp_path / "results"
    results.mkdir()
    (results / "notes.txt").write_text("mine")
    save_checkpoint(policy, results)  # other files are carried over
    assert (results / "notes.txt").read_text() == "mine"
    assert sorted(os.listdir(results)) == ["config.json", "model.safetensors", "notes.txt"]
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "config.json").write_text('{"learning_rate": 3}')
    with pytest.raises(ValueError, match="holds config.json that are not a coursekit checkpoint's"):
        save_checkpoint(policy, theirs)
    assert (theirs / "config.json").read_text() == '{"learning_rate": 3}' and os.listdir(theirs) == ["config.json"]
    data = tmp_path / "demos.npz"
    data.write_bytes(b"user data")
    with pytest.raises(ValueError, match="not a directory"):
        save_checkpoint(policy, data)
    assert data.read_bytes() == b"user data"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ckpt", "demos.npz", "results", "theirs"]  # no leftovers


def test_num_inference_steps_none_means_the_samplers_own_default():
    def steps(**kw):
        policy = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, **kw), NORMS)
        return len(policy.make_sampler().timesteps)

    assert DiffusionPolicyConfig().num_inference_steps is None
    assert steps() == 10 and steps(sampler="ddim", num_inference_steps=None) == 10
    assert steps(sampler="ddpm") == 100 and steps(sampler="ddpm", num_train_timesteps=50) == 50
    assert steps(sampler="ddpm", num_inference_steps=10) == 10 and steps(sampler="ddim", num_inference_steps=4) == 4
    policy = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, sampler="ddpm"), NORMS)
    assert len(policy.make_sampler("ddim").timesteps) == 10  # another sampler: ITS default, not T
    for bad in (0, -1, 101):
        with pytest.raises(ValueError, match=f"got {bad}"):
            policy.make_sampler("ddim", bad)  # an explicit 0 is refused, never replaced by 10
        with pytest.raises(ValueError, match=f"got {bad}"):
            DiffusionPolicyConfig(unet=TINY, num_inference_steps=bad)
    with pytest.raises(ValueError, match="got True"):
        DiffusionPolicyConfig(unet=TINY, num_inference_steps=True)
