"""One pipeline for every policy on every task: `coursekit collect`, `train`, then `eval`, TASKS x POLICY_TYPES.

Smoke runs with tiny budgets (one demonstration by the task's own expert, a few optimiser steps,
one short episode): they check the wiring -- the task records, make_policy, the feature table,
the batchers, the run folder, the checkpoint, the evaluation adapter -- for every combination of a
registered task and a registered policy type, not the learning (tests/test_train.py and the
benchmarks do). tests/test_tasks.py runs the same pipeline on a task registered by a test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from coursekit.cli import main  # noqa: E402
from coursekit.policies import POLICY_TYPES  # noqa: E402
from coursekit.tasks import TASKS  # noqa: E402


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    """One demonstration of every task, written by `coursekit collect` (its expert, its name)."""
    folder = tmp_path_factory.mktemp("pipeline")
    paths = {}
    for name in TASKS:
        paths[name] = folder / f"{name}.npz"
        assert main(["collect", name, "--episodes", "1", "--out", str(paths[name]), "--no-progress"]) == 0
    return paths


@pytest.mark.parametrize("task", list(TASKS))
@pytest.mark.parametrize("policy", sorted(POLICY_TYPES))
def test_train_then_eval_every_policy_on_every_task(policy, task, demos, tmp_path, train_then_eval):
    record = TASKS[task]
    info, summary = train_then_eval(policy, demos[task], tmp_path)
    assert info["policy_type"] == policy and info["training"]["steps"] == 3 and info["training"]["complete"]
    assert info["config"]["features"] == record.features  # the task's default, read off the data's meta
    assert summary["policy_type"] == policy and summary["task"] == task and summary["episodes"] == 1
    assert summary["max_steps"] == 4 and 0.0 <= summary["score"]
    if task == "pusht":
        assert summary["score"] <= 1.0
    else:  # the arm pair: the reward is the stage 0..4, and the task's own figures are reported
        assert summary["score"] <= 4.0
        assert set(summary["stage_rates"]) == {"1", "2", "3", "4"} and 0.0 <= summary["strict_success_rate"] <= 1.0
    if policy in ("diffusion", "flow"):
        assert summary["num_inference_steps"] == 2


@pytest.mark.parametrize("policy,task", [("diffusion", "pusht"), ("act", "transfer_cube")])
def test_a_run_folder_and_an_eval_replay_a_person_can_look_at(policy, task, demos, tmp_path, train_then_eval):
    """train writes metrics.csv + loss.png beside the checkpoint; eval --record writes a replay that a browser draws."""
    import csv

    from PIL import Image

    record = tmp_path / "replay"
    _, summary = train_then_eval(policy, demos[task], tmp_path, max_steps=6, train_steps=4, episodes=2,
                                 eval_args=("--record", str(record), "--record-episodes", "1"))
    run = tmp_path / "run"
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    assert [int(r["step"]) for r in rows] == [4] and set(rows[0]) == {"step", "loss", "lr", "samples_per_s", "wall_s"}
    assert Image.open(run / "loss.png").size[0] > 100 and (run / "config.json").is_file()
    files = summary["record"]
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


@pytest.mark.parametrize("policy", ["diffusion", "flow"])
def test_horizon_flag_trains_a_longer_chunk_that_evaluates(policy, demos, tmp_path):
    """--horizon 32 (chapter 11's longer head): the checkpoint predicts (B, 32, Da) and executes up to 31."""
    from coursekit.checkpoint import load_checkpoint

    run = tmp_path / "run"
    assert main(["train", "--policy", policy, "--data", str(demos["pusht"]), "--steps", "2", "--batch-size", "4",
                 "--warmup-steps", "1", "--out", str(run), "--threads", "1", "--no-progress", "--horizon", "32",
                 "--down-dims", "16,32"]) == 0
    policy_obj = load_checkpoint(run, device="cpu")
    spec = policy_obj.execution_spec()
    assert (spec.horizon, spec.n_obs_steps, spec.n_action_steps) == (32, 2, 8)  # Ta keeps its default
    history = np.zeros((1, 2, policy_obj.config.obs_dim), dtype=np.float32)  # (B, To, obs_dim)
    assert tuple(policy_obj.with_config(n_action_steps=31).predict_chunk(history).shape) == (1, 32, 2)
    assert main(["eval", str(run), "--episodes", "1", "--max-steps", "4", "--threads", "1", "--no-progress",
                 "--n-action-steps", "24", "--steps", "2"]) == 0
