"""benchmarks/train_head.py: a not-shipped head is trained once, resumably, and never overwritten."""

from __future__ import annotations

import pytest

import benchmarks.train_head as th


@pytest.fixture()
def tiny(tmp_path, monkeypatch):
    from coursekit.experts.pusht_planner import collect_dataset
    from coursekit.nn.unet1d import UNet1DConfig

    data = tmp_path / "demos.npz"
    collect_dataset(2, 0, progress=False).save(data)
    monkeypatch.setattr(th, "TRAINED_HEADS", tmp_path / "heads")
    monkeypatch.setitem(th.HEADS, "tiny", {"dir": "tiny_head", "policy": "flow", "steps": 3, "seed": 0,
                                           "fields": {"horizon": 16, "unet": UNet1DConfig(down_dims=(16, 32))}})
    return data


def test_trains_into_the_cache_removes_its_state_and_refuses_to_overwrite(tiny, tmp_path):
    from coursekit.checkpoint import load_checkpoint, read_checkpoint_info

    out = th.train_head("tiny", tiny, progress=False)
    assert out == tmp_path / "heads" / "tiny_head"
    policy = load_checkpoint(out, device="cpu")
    assert policy.config.horizon == 16 and read_checkpoint_info(out)["training"]["steps"] == 3
    assert sorted(p.name for p in (tmp_path / "heads").iterdir()) == ["tiny_head"], "resume state left behind"
    before = (out / "model.safetensors").read_bytes()
    with pytest.raises(SystemExit, match="tiny_head exists: tiny is trained"):
        th.train_head("tiny", tiny, progress=False)
    assert (out / "model.safetensors").read_bytes() == before


def test_missing_data_names_the_command_that_makes_it(tiny, tmp_path):
    with pytest.raises(SystemExit, match="does not exist \\(make it with: coursekit collect pusht"):
        th.train_head("tiny", tmp_path / "nope.npz", progress=False)
    assert not (tmp_path / "heads").exists(), "nothing is created before the data is found"


def test_the_command_in_row_notes_names_data_and_budget():
    text = th.command("flow-tp32")
    assert "benchmarks.train_head flow-tp32" in text and "19259 steps" in text and "--action-noise 0,5" in text
