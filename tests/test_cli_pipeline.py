"""One pipeline for every policy on every task: `coursekit train` then `coursekit eval`, 3 policies x 3 tasks.

Smoke runs with tiny budgets (a few optimiser steps, one short episode): they check the wiring
-- make_policy, the feature table, the batchers, the run folder, the checkpoint, the task
adapters -- for every combination, not the learning (tests/test_train.py and the benchmarks do).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from coursekit.cli import main  # noqa: E402
from coursekit.data import EpisodeDataset  # noqa: E402

POLICIES = ("diffusion", "regression", "act")
TASKS = ("pusht", "transfer_cube", "insertion")
SMALL = {"diffusion": ["--down-dims", "16,32"], "regression": ["--down-dims", "16,32"], "act": ["--chunk-size", "10"]}


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pipeline")
    rng = np.random.default_rng(0)
    episodes = []
    for _ in range(2):  # a synthetic PushT random walk: the expert is slow, and the wiring is what is tested
        state = 250 + np.cumsum(rng.normal(0, 5, size=(24, 5)), axis=0)
        episodes.append({"state": state, "action": state[:, :2] + rng.normal(0, 3, size=(24, 2))})
    paths = {"pusht": folder / "pusht.npz"}
    EpisodeDataset.from_episodes(episodes, {"seed": 0, "n_episodes": 2, "env_id": "synthetic"}).save(paths["pusht"])
    for task, name in (("transfer_cube", "aloha-cube"), ("insertion", "aloha-insertion")):
        paths[task] = folder / f"{task}.npz"
        assert main(["collect", name, "--episodes", "1", "--out", str(paths[task]), "--no-progress"]) == 0
    return paths


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("policy", POLICIES)
def test_train_then_eval_every_policy_on_every_task(policy, task, demos, tmp_path):
    run = tmp_path / "run"
    assert main(["train", "--policy", policy, "--data", str(demos[task]), "--steps", "3", "--batch-size", "4",
                 "--warmup-steps", "1", "--out", str(run), "--threads", "1", "--no-progress", *SMALL[policy]]) == 0
    info = json.loads((run / "config.json").read_text())
    assert info["policy_type"] == policy and info["training"]["steps"] == 3 and info["training"]["complete"]
    assert info["config"]["features"] == ("pusht_state" if task == "pusht" else "aloha_state")  # from the data
    out = tmp_path / "eval.json"
    sampling = ["--steps", "2"] if policy == "diffusion" else []
    assert main(["eval", str(run), "--episodes", "1", "--max-steps", "4", "--threads", "1", "--no-progress",
                 "--json", str(out), *sampling]) == 0
    summary = json.loads(out.read_text())
    assert summary["policy_type"] == policy and summary["task"] == task and summary["episodes"] == 1
    assert 0.0 <= summary["score"] <= (1.0 if task == "pusht" else 4.0)  # arm pair: the reward is the stage 0..4
    if task != "pusht":
        assert set(summary["stage_rates"]) == {"1", "2", "3", "4"} and 0.0 <= summary["strict_success_rate"] <= 1.0
    if policy == "diffusion":
        assert summary["sampler"] == "ddim" and summary["num_inference_steps"] == 2


@pytest.mark.parametrize("policy,task", [("diffusion", "pusht"), ("act", "transfer_cube")])
def test_a_run_folder_and_an_eval_replay_a_person_can_look_at(policy, task, demos, tmp_path):
    """train writes metrics.csv + loss.png beside the checkpoint; eval --record writes a replay that a browser draws."""
    import csv

    from PIL import Image

    run = tmp_path / "run"
    assert main(["train", "--policy", policy, "--data", str(demos[task]), "--steps", "4", "--batch-size", "4",
                 "--warmup-steps", "1", "--out", str(run), "--threads", "1", "--no-progress", *SMALL[policy]]) == 0
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    assert [int(r["step"]) for r in rows] == [4] and set(rows[0]) == {"step", "loss", "lr", "samples_per_s", "wall_s"}
    assert Image.open(run / "loss.png").size[0] > 100 and (run / "config.json").is_file()
    record = tmp_path / "replay"
    out = tmp_path / "eval.json"
    assert main(["eval", str(run), "--episodes", "2", "--max-steps", "6", "--threads", "1", "--no-progress",
                 "--record", str(record), "--record-episodes", "1", "--json", str(out)]) == 0
    files = json.loads(out.read_text())["record"]
    assert sorted(p.name for p in record.iterdir()) == ["frames.png", "replay.html"] == sorted(
        Path(f).name for f in files.values())
    assert main(["eval", str(run), "--episodes", "1", "--max-steps", "2", "--no-progress", "--record", str(record)]) == 2

    from headless_chromium import find_chromium, screenshot_html

    if find_chromium() is None:
        pytest.skip("headless chromium not installed (make test installs it as root)")
    img = np.asarray(Image.open(screenshot_html(record / "replay.html", tmp_path / "shot.png", budget_ms=1500))
                     .convert("RGB"), dtype=np.float64)[120:]  # below the caption box
    background = np.median(img[:, :4], axis=1, keepdims=True)  # meshcat's vertical gradient, row by row
    assert (np.abs(img - background).max(axis=-1) > 30).mean() > 0.05, "the replay page is blank"
