"""PushT demonstrations on disk: what collect_dataset writes, that it is deterministic, survives
a save/load round trip, refuses damaged files, and that `coursekit collect pusht` writes one."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from coursekit.data import DatasetError, EpisodeDataset
from coursekit.envs import pusht_geometry as geo


@pytest.fixture(scope="module")
def dataset() -> EpisodeDataset:
    from coursekit.experts.pusht_planner import collect_dataset

    return collect_dataset(3, seed=5, progress=False)


def test_arrays_and_meta(dataset):
    n = dataset.n_steps
    assert dataset.n_episodes == 3
    assert dataset["state"].shape == (n, 5) and dataset["action"].shape == (n, 2)
    assert dataset["coverage"].shape == (n,) and dataset["phase"].shape == (n,)
    meta = dataset.meta
    assert meta["env_id"] == "coursekit/PushT-v0" and meta["obs_type"] == "state"
    assert meta["expert"] == "coursekit.experts.pusht_planner" and meta["expert_version"]
    assert meta["seed"] == 5 and meta["n_episodes"] == 3 and meta["episode_seeds"] == [5, 6, 7]
    assert len(meta["route_choices"]) == 3 and len(meta["success_steps"]) == 3
    assert meta["coursekit_version"]
    for e in range(3):
        ep = dataset.episode(e)
        # Each episode starts at its seeded reference reset and ends at rest on the goal.
        from coursekit.envs.pusht import PushTEnv

        obs, _ = PushTEnv().reset(seed=meta["episode_seeds"][e])
        np.testing.assert_allclose(ep["state"][0, :4], obs[:4])
        assert ep["coverage"][-1] > geo.SUCCESS_THRESHOLD
        assert len(ep["state"]) == meta["finish_steps"][e] + meta["rest_steps"]
        assert meta["success_steps"][e] <= meta["finish_steps"][e]


def test_angle_is_unwrapped_and_coverage_matches_state(dataset):
    ep = dataset.episode(0)
    assert np.abs(np.diff(ep["state"][:, 4])).max() < 1.0  # no 2 pi jumps
    for t in (0, len(ep["state"]) // 2, len(ep["state"]) - 1):
        assert ep["coverage"][t] == pytest.approx(geo.coverage(ep["state"][t, 2:5]), abs=1e-9)


def test_collect_is_deterministic(dataset):
    from coursekit.experts.pusht_planner import collect_dataset

    again = collect_dataset(3, seed=5, progress=False)
    for key, arr in dataset.arrays.items():
        assert arr.dtype == again[key].dtype and arr.tobytes() == again[key].tobytes()
    assert np.array_equal(dataset.episode_ends, again.episode_ends)
    assert again.meta == dataset.meta


def test_save_load_round_trip(dataset, tmp_path):
    path = dataset.save(tmp_path / "pusht.npz")
    back = EpisodeDataset.load(path)
    assert back.meta["route_choices"] == dataset.meta["route_choices"]
    assert np.array_equal(back.episode_ends, dataset.episode_ends)
    for key, arr in dataset.arrays.items():
        assert np.array_equal(back[key], arr)


def test_damaged_files_are_refused(dataset, tmp_path):
    good = dataset.save(tmp_path / "good.npz").read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good[: len(good) // 2])
    with pytest.raises(DatasetError, match="truncated or corrupt"):
        EpisodeDataset.load(truncated)
    corrupt = tmp_path / "corrupt.npz"
    flipped = bytearray(good)
    middle = len(flipped) // 2
    flipped[middle : middle + 16] = bytes(b ^ 0xFF for b in flipped[middle : middle + 16])
    corrupt.write_bytes(bytes(flipped))
    with pytest.raises(DatasetError):
        EpisodeDataset.load(corrupt)


def test_collect_rejects_bad_arguments():
    from coursekit.experts.pusht_planner import collect_dataset

    with pytest.raises(ValueError, match="0"):
        collect_dataset(0, seed=0)
    with pytest.raises(ValueError, match="-1"):
        collect_dataset(2, seed=-1)
    for bad in (-2.0, (), (0.0, float("nan"))):
        with pytest.raises(ValueError, match="action_noise"):
            collect_dataset(2, seed=0, action_noise=bad)


def test_collect_cycles_dart_noise_levels():
    """``action_noise=(0, 10)`` alternates clean and noisy episodes; the clean ones are exactly
    the default demonstrations of the same seeds."""
    from coursekit.experts.pusht_planner import collect_dataset

    mixed = collect_dataset(2, seed=5, progress=False, action_noise=(0.0, 10.0))
    clean = collect_dataset(1, seed=5, progress=False)
    assert mixed.meta["action_noise"] == [0.0, 10.0] and mixed.meta["episode_noise"] == [0.0, 10.0]
    assert mixed.meta["episode_seeds"] == [5, 6] and clean.meta["episode_noise"] == [0.0]
    for key in ("state", "action"):
        assert np.array_equal(mixed.episode(0)[key], clean.episode(0)[key])
    from coursekit.experts.pusht_planner import noise_tag

    assert noise_tag(mixed.meta["action_noise"]) == "_noise0-10" and noise_tag([0.0]) == ""


def test_collect_command_writes_a_dataset(tmp_path):
    out = tmp_path / "demos.npz"
    exe = Path(sys.executable).with_name("coursekit")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "coursekit.cli"]
    result = subprocess.run([*cmd, "collect", "pusht", "--episodes", "3", "--seed", "0", "--out", str(out),
                             "--no-progress"], capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stderr
    loaded = EpisodeDataset.load(out)
    assert loaded.n_episodes == 3 and loaded.meta["seed"] == 0
    assert str(out) in result.stdout


def test_collect_command_dart_noise(tmp_path):
    exe = Path(sys.executable).with_name("coursekit")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "coursekit.cli"]
    out = tmp_path / "noisy.npz"
    result = subprocess.run([*cmd, "collect", "pusht", "--episodes", "2", "--action-noise", "0,10", "--out", str(out),
                             "--no-progress"], capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stderr
    assert EpisodeDataset.load(out).meta["episode_noise"] == [0.0, 10.0]
    bad = subprocess.run([*cmd, "collect", "pusht", "--episodes", "2", "--action-noise", "ten", "--out",
                          str(tmp_path / "bad.npz"), "--no-progress"], capture_output=True, text=True, timeout=240)
    assert bad.returncode != 0 and "ten" in bad.stderr and not (tmp_path / "bad.npz").exists()
