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
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coursekit.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from coursekit.config import config_from_dict, config_to_dict
from coursekit.data import MinMaxNormalizer
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.act import ACTConfig
from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
from coursekit.weights_file import config_digest, file_sha256

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
    assert recorded == {file_sha256(files[0])}
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


# ---- the weights carry the policy type and config digest they were saved with ------------------

def _three_heads(root: Path) -> dict[str, Path]:
    """Tiny diffusion, flow and regression checkpoints: the same U-Net, so the same tensor names and shapes."""
    from coursekit.policies.flow import FlowMatchingPolicy, FlowMatchingPolicyConfig
    from coursekit.policies.regression import RegressionPolicy, RegressionPolicyConfig

    torch.manual_seed(0)
    policies = {"diffusion": DiffusionPolicy(DiffusionPolicyConfig(unet=TINY), NORMS),
                "flow": FlowMatchingPolicy(FlowMatchingPolicyConfig(unet=TINY), NORMS),
                "regression": RegressionPolicy(RegressionPolicyConfig(unet=TINY), NORMS),
                "diffusion_tp32": DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, horizon=32), NORMS)}
    return {name: save_checkpoint(p, root / name) for name, p in policies.items()}


def _rebind(path: Path) -> None:
    """What a careful forger does to config.json: recompute both the weights' sha256 and the config digest."""
    info = json.loads((path / "config.json").read_text())
    info["weights"]["sha256"] = file_sha256(path / "model.safetensors")
    info["weights"]["config_sha256"] = config_digest(info)
    (path / "config.json").write_text(json.dumps(info))


def _as_older_weights(path: Path) -> None:
    """The weights as coursekit wrote them before the digest went into their metadata (like the shipped ones):
    the same tensors, metadata {format, policy_type}; config.json's sha256 follows."""
    from safetensors.torch import load_file, save_file

    w = path / "model.safetensors"
    ptype = json.loads((path / "config.json").read_text())["policy_type"]
    save_file(load_file(str(w)), str(w), metadata={"format": "coursekit-checkpoint", "policy_type": ptype})
    info = json.loads((path / "config.json").read_text())
    info["weights"]["sha256"] = file_sha256(w)
    (path / "config.json").write_text(json.dumps(info))


@pytest.mark.parametrize("older", [False, True], ids=["weights-with-digest", "older-weights"])
def test_weights_swapped_between_heads_are_refused_even_with_every_sha_updated(tmp_path, older):
    ckpts = _three_heads(tmp_path)
    if older:
        for path in ckpts.values():
            _as_older_weights(path)
    for target in ("diffusion", "flow", "regression"):
        for source in ("diffusion", "flow", "regression"):
            if source == target:
                continue
            dest = tmp_path / f"{source}_into_{target}"
            shutil.copytree(ckpts[target], dest)
            shutil.copy(ckpts[source] / "model.safetensors", dest / "model.safetensors")
            _rebind(dest)
            with pytest.raises(CheckpointError, match=f"holds the weights of a '{source}' policy but config.json says "
                                                      f"'{target}'"):
                load_checkpoint(dest, device="cpu")


def test_weights_of_another_config_of_the_same_head_are_refused(tmp_path):
    ckpts = _three_heads(tmp_path)
    shutil.copy(ckpts["diffusion_tp32"] / "model.safetensors", ckpts["diffusion"] / "model.safetensors")
    _rebind(ckpts["diffusion"])  # Tp does not change a U-Net tensor: only the digest can tell
    with pytest.raises(CheckpointError, match="was saved with another policy_type/config/normalizers"):
        load_checkpoint(ckpts["diffusion"], device="cpu")


@pytest.mark.parametrize("older", [False, True], ids=["weights-with-digest", "older-weights"])
def test_deleting_config_sha256_does_not_let_an_edit_through(tmp_path, older):
    path = _three_heads(tmp_path)["diffusion"]
    if older:
        _as_older_weights(path)
    info = json.loads((path / "config.json").read_text())
    del info["weights"]["config_sha256"]
    info["config"]["horizon"] = 32
    (path / "config.json").write_text(json.dumps(info))
    match = "lacks weights.config_sha256" if older else "was saved with another policy_type/config/normalizers"
    with pytest.raises(CheckpointError, match=match):
        load_checkpoint(path, device="cpu")
    info["config"]["horizon"] = 16  # the deletion alone: still verifiable from the weights' own metadata
    (path / "config.json").write_text(json.dumps(info))
    if older:
        with pytest.raises(CheckpointError, match="lacks weights.config_sha256"):
            load_checkpoint(path, device="cpu")
    else:
        assert load_checkpoint(path, device="cpu").config.horizon == 16


def test_weights_without_coursekit_metadata_are_refused(tmp_path):
    from safetensors.torch import load_file, save_file

    path = _three_heads(tmp_path)["diffusion"]
    save_file(load_file(str(path / "model.safetensors")), str(path / "model.safetensors"))  # a plain safetensors file
    _rebind(path)
    with pytest.raises(CheckpointError, match="carries no coursekit metadata"):
        load_checkpoint(path, device="cpu")


def test_new_weights_carry_type_and_digest_in_their_metadata(tmp_path):
    from safetensors import safe_open

    for name, path in _three_heads(tmp_path).items():
        info = json.loads((path / "config.json").read_text())
        meta = safe_open(str(path / "model.safetensors"), framework="pt").metadata()
        assert meta == {"format": "coursekit-checkpoint", "policy_type": info["policy_type"],
                        "config_sha256": config_digest(info)} == {**meta, "config_sha256": info["weights"]["config_sha256"]}, name


# ---- any hand edit of config.json: refused in one line naming the entry, or harmless ---------------


json_junk = st.recursive(st.none() | st.booleans() | st.integers(-3, 10**20) | st.floats(allow_nan=False, allow_infinity=False)
                         | st.text(max_size=6), lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=4), c, max_size=3),
                         max_leaves=5)


@pytest.fixture(scope="module")
def pusht_ckpt(tmp_path_factory):
    torch.manual_seed(0)
    policy = DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, num_inference_steps=2), NORMS)
    return save_checkpoint(policy, tmp_path_factory.mktemp("ck") / "ckpt",
                           dataset_meta={"env_id": "coursekit/PushT-v0", "episode_seeds": [0, 1]}, training={"steps": 3})


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_edit_of_config_json_is_one_clear_line_or_harmless(pusht_ckpt, tmp_path_factory, data, capsys):
    from coursekit.cli import main

    info = json.loads((pusht_ckpt / "config.json").read_text())
    path = data.draw(st.sampled_from(_paths(info)))
    bad = json.loads(json.dumps(info))
    dropped = data.draw(st.booleans())
    if dropped:
        _drop(bad, path)
    else:
        _set(bad, path, data.draw(json_junk))
    work = tmp_path_factory.mktemp("edit") / "ckpt"
    shutil.copytree(pusht_ckpt, work)
    (work / "config.json").write_text(json.dumps(bad))
    before = {p.name: p.read_bytes() for p in work.iterdir()}
    capsys.readouterr()
    rc = main(["eval", str(work), "--episodes", "1", "--max-steps", "1", "--no-progress"])
    err = capsys.readouterr().err
    assert rc in (0, 2), err
    if rc == 2:  # one line from the checkpoint's checks, never the catch-all for an unexpected exception
        assert err.count("\n") == 1 and err.startswith("coursekit eval: error: ") and "--debug" not in err, err
    elif path[0] in ("policy_type", "config", "normalizers") or path == ("weights", "sha256") or \
            (path == ("weights", "file") and not dropped):  # (a missing weights.file means model.safetensors)
        assert bad == info, f"an edit of {path} was accepted"
    assert {p.name: p.read_bytes() for p in work.iterdir()} == before
