"""`coursekit train --policy act` and `coursekit eval` on ALOHA demonstrations (smoke, tiny budgets)."""

from __future__ import annotations

import json

import pytest

from coursekit.cli import main


@pytest.fixture(scope="module")
def cube_demos(tmp_path_factory):
    path = tmp_path_factory.mktemp("act_cli") / "cube.npz"
    assert main(["collect", "aloha-cube", "--episodes", "2", "--seed", "0", "--out", str(path), "--no-progress"]) == 0
    return path


def test_train_act_then_eval_on_its_task(cube_demos, tmp_path):
    ckpt = tmp_path / "act"
    assert main(["train", "--policy", "act", "--recipe", "cpu", "--data", str(cube_demos), "--steps", "3",
                 "--chunk-size", "10", "--out", str(ckpt), "--threads", "1", "--no-progress"]) == 0
    config = json.loads((ckpt / "config.json").read_text())
    assert config["policy_type"] == "act" and config["config"]["chunk_size"] == 10
    assert config["config"]["features"] == "aloha_state"  # read from the data
    out = tmp_path / "eval.json"
    assert main(["eval", str(ckpt), "--episodes", "1", "--max-steps", "15", "--no-ensembling", "--threads", "1",
                 "--json", str(out), "--no-progress"]) == 0
    summary = json.loads(out.read_text())
    assert summary["task"] == "transfer_cube" and summary["temporal_ensembling"] is False
    assert set(summary["stage_rates"]) == {"1", "2", "3", "4"} and 0.0 <= summary["strict_success_rate"] <= 1.0


def test_options_a_policy_lacks_are_refused_before_any_work(cube_demos, tmp_path, capsys):
    assert main(["train", "--policy", "diffusion", "--chunk-size", "10", "--data", str(cube_demos),
                 "--steps", "1", "--out", str(tmp_path / "x")]) == 2
    assert "--chunk-size 10 does not apply to --policy diffusion" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    assert main(["train", "--policy", "act", "--down-dims", "16,32", "--data", str(cube_demos),
                 "--steps", "1", "--out", str(tmp_path / "y")]) == 2
    assert "--down-dims 16,32 does not apply to --policy act" in capsys.readouterr().err
    assert not (tmp_path / "y").exists()


def test_train_refuses_an_output_folder_it_did_not_write(cube_demos, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert main(["train", "--policy", "act", "--data", str(cube_demos), "--steps", "1", "--out", str(out)]) == 2
    assert "not a coursekit run" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "keep me" and sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def test_eval_overrides_are_validated_and_policy_specific(cube_demos, tmp_path, capsys):
    ckpt = tmp_path / "act"
    assert main(["train", "--policy", "act", "--data", str(cube_demos), "--steps", "1", "--chunk-size", "10",
                 "--out", str(ckpt), "--threads", "1", "--no-progress"]) == 0
    common = ["eval", str(ckpt), "--episodes", "1", "--max-steps", "2", "--no-progress"]
    assert main([*common, "--ensemble-decay", "-1"]) == 2
    assert "argument --ensemble-decay: must be a finite number >= 0, got '-1'" in capsys.readouterr().err
    assert main([*common, "--ddim-spacing", "trailing"]) == 2
    assert "--ddim-spacing trailing does not apply to" in capsys.readouterr().err
    assert main([*common, "--sampler", "ddpm"]) == 2
    assert "--sampler ddpm does not apply to" in capsys.readouterr().err
    # the loaded checkpoint is untouched: overrides live in a copy
    assert json.loads((ckpt / "config.json").read_text())["config"]["ensemble_decay"] == 0.01


def test_train_act_from_the_top_camera_then_eval(cube_demos, tmp_path):
    ckpt = tmp_path / "act_camera"
    assert main(["train", "--policy", "act", "--recipe", "cpu", "--features", "aloha_image", "--vision", "arm_pair",
                 "--data", str(cube_demos), "--steps", "2", "--chunk-size", "10", "--out", str(ckpt), "--threads", "1",
                 "--no-progress"]) == 0
    config = json.loads((ckpt / "config.json").read_text())["config"]
    assert (config["features"], config["obs_type"]) == ("aloha_image", "image")
    assert tuple(config["vision"]["image_size"]) == (96, 128) and config["vision"]["random_crops"] is False
    out = tmp_path / "eval.json"
    assert main(["eval", str(ckpt), "--episodes", "1", "--max-steps", "5", "--threads", "1", "--json", str(out),
                 "--no-progress"]) == 0
    assert json.loads(out.read_text())["task"] == "transfer_cube"
