"""EpisodeDataset: round trip, atomic writes, and refusal of bad files."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from coursekit.data import DatasetError, EpisodeDataset


def _dataset(seed: int = 0) -> EpisodeDataset:
    rng = np.random.default_rng(seed)
    eps = [{"obs": rng.normal(size=(n, 5)), "action": rng.normal(size=(n, 2))} for n in (4, 7, 3)]
    return EpisodeDataset.from_episodes(eps, meta={"env_id": "coursekit/PushT-v0", "seed": seed})


def test_from_episodes_layout():
    ds = _dataset()
    assert ds.n_episodes == 3 and ds.n_steps == 14
    np.testing.assert_array_equal(ds.episode_ends, [4, 11, 14])
    np.testing.assert_array_equal(ds.episode_starts, [0, 4, 11])
    np.testing.assert_array_equal(ds.episode_lengths, [4, 7, 3])
    np.testing.assert_array_equal(ds.episode(1)["obs"], ds["obs"][4:11])
    np.testing.assert_array_equal(ds.episode(-1)["action"], ds["action"][11:])
    with pytest.raises(IndexError, match="out of range"):
        ds.episode(3)


def test_round_trip_is_exact(tmp_path):
    ds = _dataset()
    path = ds.save(tmp_path / "demo.npz")
    back = EpisodeDataset.load(path)
    assert back.meta["env_id"] == "coursekit/PushT-v0" and back.meta["format_version"] == 1
    np.testing.assert_array_equal(back.episode_ends, ds.episode_ends)
    for key in ds.arrays:
        np.testing.assert_array_equal(back[key], ds[key])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.npz"]  # no temporary left behind


def test_missing_file_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.npz"):
        EpisodeDataset.load(tmp_path / "nope.npz")


@pytest.mark.parametrize("cut", [0.5, 0.9])
def test_truncated_file_is_refused(tmp_path, cut):
    path = _dataset().save(tmp_path / "demo.npz")
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * cut)])
    with pytest.raises(DatasetError, match="truncated or corrupt"):
        EpisodeDataset.load(path)


def test_flipped_bytes_are_refused(tmp_path):
    path = _dataset().save(tmp_path / "demo.npz")
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside a compressed member: the zip CRC or inflate must notice
    path.write_bytes(bytes(data))
    with pytest.raises(DatasetError):
        EpisodeDataset.load(path)


def test_not_a_dataset_is_refused(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, x=np.zeros(3))
    with pytest.raises(DatasetError, match="not a coursekit dataset"):
        EpisodeDataset.load(path)


def test_failed_save_keeps_the_old_file(tmp_path, monkeypatch):
    path = _dataset(0).save(tmp_path / "demo.npz")
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        _dataset(1).save(path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.npz"]


def test_inconsistent_arrays_are_refused():
    with pytest.raises(DatasetError, match="rows"):
        EpisodeDataset({"obs": np.zeros((5, 2))}, episode_ends=np.array([2, 6]))
    with pytest.raises(DatasetError, match="increasing"):
        EpisodeDataset({"obs": np.zeros((6, 2))}, episode_ends=np.array([4, 2, 6]))
    with pytest.raises(DatasetError, match="episode 1"):
        EpisodeDataset.from_episodes([{"a": np.zeros(2)}, {"b": np.zeros(2)}])


def test_zip_container_is_a_real_npz(tmp_path):
    path = _dataset().save(tmp_path / "demo.npz")
    with zipfile.ZipFile(path) as zf:
        assert zf.testzip() is None
        assert {"obs.npy", "action.npy", "episode_ends.npy", "__meta__.npy"} <= set(zf.namelist())


def test_saved_file_has_ordinary_permissions(tmp_path):
    import os
    import stat

    umask = os.umask(0)
    os.umask(umask)
    path = _dataset().save(tmp_path / "demo.npz")
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
