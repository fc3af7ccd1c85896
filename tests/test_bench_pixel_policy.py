"""benchmarks/bench_pixel_policy.py: stage 1 measures its keypoint error on episodes it never trained on; --ship never overwrites."""

from __future__ import annotations

import numpy as np
import pytest

import benchmarks.bench_pixel_policy as bpp


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    from coursekit.experts.pusht_planner import collect_dataset

    path = tmp_path_factory.mktemp("data") / "demos.npz"
    collect_dataset(3, 0, progress=False).save(path)
    return path


def test_frames_and_keypoints_line_up(demos):
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.envs.pusht_render import PushTRenderer

    frames, keypoints, episode = bpp.frames_and_keypoints(demos, None)
    ds = EpisodeDataset.load(demos)
    assert frames.shape == (ds.n_steps, 3, 96, 96) and frames.dtype == np.uint8
    assert keypoints.shape == (ds.n_steps, 16)  # 8 corners of the T, (x, y) each
    assert np.array_equal(np.bincount(episode), ds.episode_lengths)
    i = int(ds.episode_ends[0])  # the first frame of episode 1 is its own state's picture
    assert np.array_equal(frames[i], PushTRenderer((96, 96)).render(ds["state"][i]).transpose(2, 0, 1))


def test_pretrain_rows_are_measured_on_the_held_out_episode(demos, tmp_path, monkeypatch):
    import benchmarks.results

    rows = []
    monkeypatch.setattr(benchmarks.results, "record", lambda *a, **k: rows.append((a, k)))
    bpp.main(["--only", "pretrain", "--pretrain-steps", "2", "--batch-size", "8", "--episodes-limit", "3",
              "--data", str(demos), "--out", str(tmp_path)])
    (err, err_kw), (speed, _), (render, _) = rows
    assert render[1].startswith("rendering the demonstrations' frames") and render[3] == "frames/s" and render[2] > 0
    _, _, episode = bpp.frames_and_keypoints(demos, 3)
    assert err[1] == "stage 1: held-out block keypoint error" and err[3] == "px"
    assert err_kw["n"] == int(np.sum(episode == 2)) and err_kw["interval"][0] <= err[2] <= err_kw["interval"][1]
    assert speed[3] == "images/s" and speed[2] > 0
    assert [p.name for p in tmp_path.iterdir()] == ["encoder_pretrained_s2_b8_seed0.pt"]
    bpp.main(["--only", "pretrain", "--pretrain-steps", "2", "--batch-size", "8", "--episodes-limit", "3",
              "--data", str(demos), "--out", str(tmp_path), "--no-random-crops"])  # the augmentation off: its own rows
    (plain, plain_kw), *_ = rows[3:]
    assert plain[1] == "stage 1 without random crops: held-out block keypoint error"
    assert plain[4].endswith("--no-random-crops") and "centre (no augmentation) crops" in plain_kw["note"]
    assert (tmp_path / "encoder_pretrained_s2_b8_seed0_nocrops.pt").is_file()
    mtime = (tmp_path / "encoder_pretrained_s2_b8_seed0.pt").stat().st_mtime_ns
    bpp.main(["--only", "pretrain", "--pretrain-steps", "2", "--batch-size", "8", "--episodes-limit", "3",
              "--data", str(demos), "--out", str(tmp_path)])  # finished before: loaded and measured, not retrained
    assert (tmp_path / "encoder_pretrained_s2_b8_seed0.pt").stat().st_mtime_ns == mtime
    assert rows[6][0][2] == err[2] and rows[7][0][2] == speed[2]  # the same rows again


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_two_stage_policy_trains_on_the_frozen_stage1_encoder(demos, tmp_path, monkeypatch):
    import torch

    import benchmarks.results
    from coursekit.checkpoint import load_checkpoint

    rows = []
    monkeypatch.setattr(benchmarks.results, "record", lambda *a, **k: rows.append((a, k)))
    common = ["--pretrain-steps", "2", "--batch-size", "8", "--data", str(demos), "--out", str(tmp_path)]
    with pytest.raises(SystemExit, match="no stage-1 encoder"):
        bpp.main(["--only", "policy", "--policy-steps", "2", "--episodes", "1", *common])
    bpp.main(["--only", "pretrain", "policy", "--policy-steps", "2", "--episodes", "1", "--episodes-limit", "3", *common])
    score, speed = rows[3:]
    assert score[0][1] == "DP from pixels, two-stage: score" and score[1]["n"] == 1
    assert speed[0][3] == "samples/s"
    stage1 = torch.load(tmp_path / "encoder_pretrained_s2_b8_seed0.pt", weights_only=False)["encoder"]
    policy = load_checkpoint(tmp_path / "dp_two-stage_p2_s2_seed0", device="cpu")
    for k, v in stage1.items():  # frozen: the policy's encoder is stage 1's, bit for bit (EMA of a constant)
        assert torch.equal(policy.vision_encoder.state_dict()[k].float(), v.float()), k
    assert not list(tmp_path.glob(".*.state.pt")), "the resume state outlived its run"
    shipped = tmp_path / "pusht_diffusion_pixels"
    monkeypatch.setattr(bpp, "SHIPPED", shipped)
    bpp.main(["--only", "policy", "--policy-steps", "2", "--episodes", "1", "--episodes-limit", "3", "--ship", *common])
    (section, row_name, *_), kw = rows[-1]
    assert section == bpp.SECTION and row_name == "shipped pixel checkpoint score, DDIM-10 (notebook 12)" and kw["n"] == 1
    from safetensors.torch import load_file

    assert {t.dtype for t in load_file(shipped / "model.safetensors").values()} <= {torch.float16, torch.int64}
    with pytest.raises(SystemExit, match="never overwritten"):  # checked before any work
        bpp.main(["--only", "policy", "--policy-steps", "2", "--episodes", "1", "--ship", *common])
