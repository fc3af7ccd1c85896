"""Trainer: LR schedule vs diffusers, EMA formula, determinism, budgets, batching, bad data, CLI smoke."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from coursekit.data import EpisodeDataset, SequenceWindows
from coursekit.data.batches import EpochSampler, WindowBatcher
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.factory import make_policy
from coursekit.train import EMA, TrainConfig, ema_decay, lr_factor, train

TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


def synthetic_pusht(n_episodes: int = 6, length: int = 30, seed: int = 0) -> EpisodeDataset:
    rng = np.random.default_rng(seed)
    episodes = []
    for _ in range(n_episodes):
        state = 250 + np.cumsum(rng.normal(0, 5, size=(length, 5)), axis=0)
        state[:, 4] = np.cumsum(rng.normal(0, 0.3, size=length))
        episodes.append({"state": state, "action": state[:, :2] + rng.normal(0, 3, size=(length, 2))})
    return EpisodeDataset.from_episodes(episodes, {"seed": 0, "n_episodes": n_episodes, "env_id": "synthetic"})


@pytest.mark.parametrize("warmup, total", [(500, 1500), (10, 100), (0, 50)])
def test_lr_schedule_matches_diffusers_cosine_with_warmup(warmup, total):
    from diffusers.optimization import get_cosine_schedule_with_warmup

    opt = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=1.0)
    sched = get_cosine_schedule_with_warmup(opt, num_warmup_steps=warmup, num_training_steps=total)
    for step in range(total):
        progress = (step - warmup) / max(1, total - warmup)
        assert lr_factor(step, warmup, progress) == pytest.approx(opt.param_groups[0]["lr"], abs=1e-9), step
        opt.step()
        sched.step()


def test_lr_schedule_closed_form_points():
    assert lr_factor(0, 500, 0.0) == 0.0
    assert lr_factor(250, 500, 0.0) == 0.5
    assert lr_factor(500, 500, 0.0) == 1.0
    assert lr_factor(900, 500, 0.5) == pytest.approx(0.5)
    assert lr_factor(900, 500, 1.0) == pytest.approx(0.0)
    assert lr_factor(900, 500, 0.7, "constant") == 1.0


def test_ema_decay_formula():
    for step in (0, 1, 2, 10, 100, 5000):
        assert ema_decay(step) == pytest.approx(min(0.9999, 1 - (1 + step) ** -0.75))
    assert ema_decay(0) == 0.0
    assert ema_decay(10**9) == 0.9999
    assert ema_decay(3, power=1.0, max_decay=0.5) == 0.5


def test_ema_update_is_the_moving_average():
    torch.manual_seed(0)
    model = torch.nn.Linear(3, 2)
    ema = EMA(model)
    expected = model.weight.detach().clone()
    for step in range(4):
        with torch.no_grad():
            model.weight.add_(torch.randn_like(model.weight))
        ema.update(model, step)
        d = 1 - (1 + step) ** -0.75
        expected = d * expected + (1 - d) * model.weight.detach()
    assert torch.allclose(ema.model.weight, expected, atol=1e-6)
    assert not ema.model.weight.requires_grad


def test_window_batcher_matches_sequence_windows_gather():
    ds = synthetic_pusht()
    obs = {"obs": ds["state"].astype(np.float32)}
    b = WindowBatcher(obs, ds["action"], ds.episode_ends, batch_size=7, seed=3)
    which = torch.tensor([0, 5, 17, len(b) - 1])
    batch = b.batch(which)
    windows = SequenceWindows.build(ds.episode_ends, 16, 2, 8)
    o, a = windows.gather(obs["obs"], ds["action"], which.numpy())
    np.testing.assert_allclose(batch["obs"].numpy(), o, rtol=1e-6)
    np.testing.assert_allclose(batch["action"].numpy(), a.astype(np.float32), rtol=1e-6)
    first = [x["action"] for _, x in zip(range(3), b)]
    again = [x["action"] for _, x in zip(range(3), WindowBatcher(obs, ds["action"], ds.episode_ends, batch_size=7, seed=3))]
    assert all(torch.equal(x, y) for x, y in zip(first, again))


def test_epoch_sampler_visits_every_item_once_per_epoch():
    it = iter(EpochSampler(10, 3, torch.Generator().manual_seed(0)))
    epoch = torch.cat([next(it) for _ in range(3)])  # 3 full batches; the 10th item's batch is dropped
    assert len(set(epoch.tolist())) == 9


def test_nan_in_training_data_is_a_clear_error():
    ds = synthetic_pusht()
    action = ds["action"].copy()
    action[13, 1] = np.nan
    with pytest.raises(ValueError, match="NaN.*row 13"):
        WindowBatcher({"obs": ds["state"]}, action, ds.episode_ends)


def test_training_is_deterministic_by_seed():
    ds = synthetic_pusht()
    runs = []
    for seed in (0, 0, 1):
        policy, batches, _ = make_policy("diffusion", ds, batch_size=16, seed=seed, unet=TINY)
        cfg = TrainConfig(max_steps=12, warmup_steps=2, lr=1e-3, seed=seed, log_every=4, progress=False)
        runs.append(train(policy, batches, cfg))
    w = [torch.cat([p.flatten() for p in r.policy.parameters()]) for r in runs]
    assert torch.equal(w[0], w[1]) and not torch.equal(w[0], w[2])
    assert [h["loss"] for h in runs[0].history] == [h["loss"] for h in runs[1].history]
    s = runs[0].summary
    assert s["steps"] == 12 and s["samples"] == 12 * 16 and s["complete"]  # the rows trained on, not TrainConfig's 256
    # EMA weights differ from the raw ones and are what the result hands back
    raw = torch.cat([p.flatten() for p in runs[0].raw_policy.parameters()])
    assert not torch.equal(raw, w[0]) and not runs[0].policy.training


def test_time_budget_stops_the_run_and_checkpoints(tmp_path):
    ds = synthetic_pusht()
    from coursekit.checkpoint import CheckpointSaver

    policy, batches, _ = make_policy("regression", ds, batch_size=8, unet=TINY)
    cfg = TrainConfig(minutes=0.02, warmup_steps=0, progress=False, ema=False, log_every=1)
    result = train(policy, batches, cfg, callbacks=[CheckpointSaver(tmp_path / "ckpt", dataset_meta=ds.meta)])
    assert 1 <= result.summary["steps"] and result.summary["seconds"] < 30
    lrs = [h["lr"] for h in result.history]  # cosine over the fraction of the time budget used
    assert lrs[0] == pytest.approx(1e-4) and all(b <= a for a, b in zip(lrs, lrs[1:]))
    info = json.loads((tmp_path / "ckpt" / "config.json").read_text())
    assert info["training"]["steps"] == result.summary["steps"] and info["dataset"]["env_id"] == "synthetic"
    assert result.policy is policy  # no EMA: the trained policy itself


def test_a_budget_that_ends_before_the_first_step_writes_no_checkpoint(tmp_path):
    policy, batches, _ = make_policy("regression", synthetic_pusht(), batch_size=8, unet=TINY)
    from coursekit.checkpoint import CheckpointSaver

    cfg = TrainConfig(minutes=1e-300, warmup_steps=0, progress=False, ema=False)
    with pytest.raises(ValueError, match="the budget ended before the first optimiser step"):
        train(policy, batches, cfg, callbacks=[CheckpointSaver(tmp_path / "ckpt")])
    assert list(tmp_path.iterdir()) == []


def test_named_recipes():
    paper = TrainConfig.recipe("paper", max_steps=5)
    assert (paper.lr, paper.batch_size, paper.betas, paper.weight_decay, paper.warmup_steps) == (1e-4, 256, (0.95, 0.999), 1e-6, 500)
    cpu = TrainConfig.recipe("cpu", minutes=20, lr=3e-4)
    assert (cpu.lr, cpu.batch_size, cpu.minutes) == (3e-4, 128, 20)
    with pytest.raises(ValueError, match="unknown training recipe 'fast'"):
        TrainConfig.recipe("fast", max_steps=5)


def test_train_config_validation_shows_bad_value():
    with pytest.raises(ValueError, match="max_steps or minutes"):
        TrainConfig()
    with pytest.raises(ValueError, match="-3"):
        TrainConfig(max_steps=-3)
    with pytest.raises(ValueError, match="lr_schedule"):
        TrainConfig(max_steps=3, lr_schedule="step")


def test_cli_train_then_eval_smoke(tmp_path, capsys):
    """`coursekit train` a few steps on a tiny dataset, then `coursekit eval` 2 short episodes."""
    from coursekit.cli import main

    data = tmp_path / "demos.npz"
    synthetic_pusht().save(data)
    out = tmp_path / "ckpt"
    assert main(["train", "--policy", "diffusion", "--data", str(data), "--steps", "2", "--batch-size", "4",
                 "--out", str(out), "--no-progress", "--warmup-steps", "1"]) == 0
    assert (out / "model.safetensors").is_file() and (out / "config.json").is_file()
    summary_file = tmp_path / "eval.json"
    assert main(["eval", str(out), "--episodes", "2", "--max-steps", "3", "--steps", "2", "--no-progress",
                 "--json", str(summary_file)]) == 0
    summary = json.loads(summary_file.read_text())
    assert summary["episodes"] == 2 and 0.0 <= summary["score"] <= 1.0 and summary["num_inference_steps"] == 2
    assert summary["first_timestep"] == 50  # leading spacing (the paper's): 50, 0
    assert main(["eval", str(out), "--episodes", "2", "--max-steps", "3", "--steps", "2", "--no-progress",
                 "--ddim-spacing", "trailing", "--json", str(summary_file)]) == 0
    assert json.loads(summary_file.read_text())["first_timestep"] == 99  # trailing: 99, 49
    assert main(["eval", str(tmp_path / "nope"), "--no-progress"]) == 2  # clear error, no traceback
    assert "not found" in capsys.readouterr().err
    assert not math.isnan(summary["ms_per_chunk"])


def test_cli_train_image_policy_smoke(tmp_path):
    """`coursekit train --features pusht_image` renders frames and trains (the documented GPU command, one step on CPU)."""
    from coursekit.checkpoint import read_checkpoint_info
    from coursekit.cli import main

    data = tmp_path / "demos.npz"
    synthetic_pusht(n_episodes=2, length=12).save(data)
    out = tmp_path / "img"
    assert main(["train", "--features", "pusht_image", "--data", str(data), "--steps", "1", "--batch-size", "2",
                 "--down-dims", "16,32", "--out", str(out), "--no-progress", "--device", "cpu"]) == 0
    cfg = read_checkpoint_info(out)["config"]
    assert cfg["obs_type"] == "image" and cfg["vision"]["image_size"] == [96, 96] and cfg["unet"]["down_dims"] == [16, 32]
    from coursekit.checkpoint import load_checkpoint

    policy = load_checkpoint(out, device="cpu")
    assert policy.config.vision.image_size == (96, 96) and policy.vision_encoder is not None


def test_optimizer_is_adamw_with_the_papers_settings():
    from coursekit.train import make_optimizer

    torch.manual_seed(0)
    a, b = torch.nn.Linear(4, 3), torch.nn.Linear(4, 3)
    b.load_state_dict(a.state_dict())
    cfg = TrainConfig(max_steps=1)
    opt_a = make_optimizer(a, cfg)
    opt_b = torch.optim.AdamW(b.parameters(), lr=1e-4, betas=(0.95, 0.999), weight_decay=1e-6, foreach=False)
    assert opt_a.param_groups[0]["betas"] == (0.95, 0.999) and opt_a.param_groups[0]["weight_decay"] == 1e-6
    for _ in range(3):
        x = torch.randn(8, 4)
        for m, opt in ((a, opt_a), (b, opt_b)):
            opt.zero_grad()
            m(x).square().mean().backward()
            opt.step()
    torch.testing.assert_close(a.weight, b.weight, rtol=1e-6, atol=1e-7)


def test_cli_init_from_continues_from_the_checkpoint_weights(tmp_path, capsys):
    """--init-from: the new run starts from the old weights (with lr ~0 they stay put) and records its history."""
    from coursekit.checkpoint import load_checkpoint, read_checkpoint_info
    from coursekit.cli import main

    data = tmp_path / "demos.npz"
    synthetic_pusht().save(data)
    first, second = tmp_path / "first", tmp_path / "second"
    common = ["--data", str(data), "--batch-size", "4", "--down-dims", "16,32", "--no-progress", "--warmup-steps", "0"]
    assert main(["train", "--steps", "3", "--out", str(first), *common]) == 0
    assert main(["train", "--steps", "2", "--lr", "1e-12", "--init-from", str(first), "--out", str(second), *common]) == 0
    a, b = load_checkpoint(first, device="cpu").state_dict(), load_checkpoint(second, device="cpu").state_dict()
    for name in a:
        torch.testing.assert_close(b[name], a[name], atol=1e-6, rtol=0, msg=name)
    prior = read_checkpoint_info(second)["training"]["init_from"]
    assert prior["path"] == str(first) and prior["steps"] == 3
    # A fresh run from the same seed is NOT the first checkpoint: the weights really came from --init-from.
    fresh = tmp_path / "fresh"
    assert main(["train", "--steps", "2", "--lr", "1e-12", "--out", str(fresh), *common]) == 0
    c = load_checkpoint(fresh, device="cpu").state_dict()
    assert any((c[n] - a[n]).abs().max() > 1e-4 for n in a)

    # Mismatches are refused with the difference named, and nothing is written.
    capsys.readouterr()
    bad = tmp_path / "bad"
    assert main(["train", "--steps", "1", "--init-from", str(first), "--out", str(bad),
                 *[x if x != "16,32" else "16,48" for x in common]]) == 2
    assert "unet" in capsys.readouterr().err and not bad.exists()
    assert main(["train", "--steps", "1", "--policy", "regression", "--init-from", str(first), "--out", str(bad), *common]) == 2
    assert "'diffusion' policy, expected 'regression'" in capsys.readouterr().err and not bad.exists()


def test_callbacks_get_log_records_and_the_final_policy_and_train_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    ds = synthetic_pusht()
    policy, batches, _ = make_policy("regression", ds, batch_size=8, unet=TINY)
    logged, saved = [], []

    class Spy:
        def on_log(self, record):
            logged.append(dict(record))

        def on_checkpoint(self, pol, summary):
            saved.append((pol, dict(summary)))

    cfg = TrainConfig(max_steps=5, warmup_steps=0, log_every=2, progress=False, ema=False)
    result = train(policy, batches, cfg, callbacks=[Spy(), object()])  # a callback may define only some hooks
    assert [r["step"] for r in logged] == [2, 4, 5]
    assert all(set(r) == {"step", "loss", "lr", "samples_per_s", "wall_s"} for r in logged)
    assert logged[-1]["loss"] == pytest.approx(result.history[-1]["loss"])
    assert len(saved) == 1 and saved[0][0] is result.policy and saved[0][1]["complete"] and saved[0][1]["steps"] == 5
    assert list(tmp_path.iterdir()) == []
