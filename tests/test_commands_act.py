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


def test_act_options_are_refused_for_diffusion_features(cube_demos, tmp_path, capsys):
    assert main(["train", "--policy", "diffusion", "--features", "aloha_state", "--data", str(cube_demos),
                 "--steps", "1", "--out", str(tmp_path / "x")]) == 2
    assert "--features aloha_state is for --policy act" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
