"""`coursekit export lerobot` / `coursekit import lerobot`: the exact round trip, the v3.0 layout, training on it.

Data sets are real: scripted PushT demonstrations (with and without camera frames rendered from
their states, as an 'image' array holds them) and one scripted episode of each arm-pair task.
The layout is checked against the numbers it must hold (the data set's own arrays, numpy's
statistics, our env's keypoints); LeRobot's own reader is checked by
``benchmarks/check_lerobot_reader.py`` (it needs the lerobot package, so not here).
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pyarrow.parquet as pq
import pytest

pytest.importorskip("mujoco")

from coursekit.cli import main  # noqa: E402
from coursekit.data import lerobot_format  # noqa: E402
from coursekit.data.episodes import EpisodeDataset  # noqa: E402
from coursekit.data.lerobot_pusht import lerobot_keypoints  # noqa: E402
from coursekit.data.lerobot_reader import read_folder  # noqa: E402


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    """Path of each data set: pusht (2 episodes), pusht_image (the same with frames), transfer_cube, insertion."""
    from coursekit.envs.pusht_render import PushTRenderer
    from coursekit.experts.aloha_scripted import collect_insertion, collect_transfer_cube
    from coursekit.experts.pusht_planner import collect_dataset

    root = tmp_path_factory.mktemp("demos")
    pusht = collect_dataset(2, 0, progress=False)
    renderer = PushTRenderer(96)
    images = np.stack([renderer.render(s) for s in pusht["state"]])  # (N, 96, 96, 3) uint8
    sets = {"pusht": pusht, "pusht_image": EpisodeDataset({**pusht.arrays, "image": images}, pusht.episode_ends, pusht.meta),
            "transfer_cube": collect_transfer_cube(1, 0, progress=False), "insertion": collect_insertion(1, 0, progress=False)}
    paths = {name: root / f"{name}.npz" for name in sets}
    for name, dataset in sets.items():
        dataset.save(paths[name])
    return paths


@pytest.fixture(scope="module")
def exported(demos, tmp_path_factory):
    """Folder of each data set's export (CLI)."""
    root = tmp_path_factory.mktemp("exports")
    for name, path in demos.items():
        assert main(["export", "lerobot", str(path), str(root / name)]) == 0
    return {name: root / name for name in demos}


def assert_same(a: EpisodeDataset, b: EpisodeDataset) -> None:
    assert sorted(a.arrays) == sorted(b.arrays)
    for key in a.arrays:
        assert a[key].dtype == b[key].dtype and a[key].shape == b[key].shape, key
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    np.testing.assert_array_equal(a.episode_ends, b.episode_ends)
    assert a.meta == b.meta


@pytest.mark.parametrize("name", ["pusht", "pusht_image", "transfer_cube", "insertion"])
def test_export_then_import_gives_the_data_set_back_exactly(name, demos, exported, tmp_path):
    assert main(["import", "lerobot", str(exported[name]), str(tmp_path / "back.npz")]) == 0
    assert_same(EpisodeDataset.load(demos[name]), EpisodeDataset.load(tmp_path / "back.npz"))


def frames_of(folder):
    table = pq.read_table(sorted((folder / "data").glob("*/*.parquet"))[0])
    return table, json.loads((folder / "meta" / "info.json").read_text())


def test_pusht_folder_is_lerobot_v3_with_lerobots_pusht_features(demos, exported):
    data = EpisodeDataset.load(demos["pusht_image"])
    table, info = frames_of(exported["pusht_image"])
    n, ends = data.n_steps, data.episode_ends
    assert info["codebase_version"] == "v3.0" and info["fps"] == 10 and info["total_frames"] == n
    assert info["total_episodes"] == 2 and info["total_tasks"] == 1 and info["splits"] == {"train": "0:2"}
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet" and info["video_path"] is None
    assert (info["chunks_size"], info["data_files_size_in_mb"], info["video_files_size_in_mb"]) == (1000, 100, 200)
    features = info["features"]
    lerobot_keys = {"observation.state", "observation.environment_state", "observation.image", "action", "next.reward",
                    "next.done", "next.success", "timestamp", "frame_index", "episode_index", "index", "task_index"}
    assert lerobot_keys | {f"coursekit.{k}" for k in data.arrays if k != "image"} == set(features)
    assert features["observation.environment_state"]["shape"] == [16] and features["action"]["dtype"] == "float32"
    assert features["observation.image"] == {"dtype": "image", "shape": [96, 96, 3], "names": ["height", "width", "channel"]}
    assert set(table.column_names) == set(features)
    col = {k: table.column(k).to_numpy(zero_copy_only=False) for k in ("frame_index", "episode_index", "index", "timestamp")}
    np.testing.assert_array_equal(col["index"], np.arange(n))
    np.testing.assert_array_equal(col["frame_index"], np.r_[np.arange(ends[0]), np.arange(ends[1] - ends[0])])
    np.testing.assert_allclose(col["timestamp"], col["frame_index"] / 10.0, atol=1e-6)
    state = np.stack(table.column("observation.state").to_numpy(zero_copy_only=False))
    env_state = np.stack(table.column("observation.environment_state").to_numpy(zero_copy_only=False))
    np.testing.assert_array_equal(state, data["state"][:, :2].astype(np.float32))
    np.testing.assert_array_equal(env_state, lerobot_keypoints(data["state"]).astype(np.float32))
    done = table.column("next.done").to_numpy(zero_copy_only=False)
    np.testing.assert_array_equal(np.flatnonzero(done), ends - 1)  # the last frame of each episode, only
    assert table.column("observation.image").type.names == ["bytes", "path"]  # HF datasets' Image storage (PNG)


def test_meta_tables_and_stats(demos, exported):
    folder = exported["pusht_image"]
    data = EpisodeDataset.load(demos["pusht_image"])
    tasks = pq.read_table(folder / "meta" / "tasks.parquet")
    assert tasks.to_pydict() == {"task_index": [0], "task": ["Push the T-shaped block onto the T-shaped target."]}
    assert json.loads(tasks.schema.metadata[b"pandas"])["index_columns"] == ["task"]  # pandas.read_parquet's index
    episodes = pq.read_table(folder / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pydict()
    starts = data.episode_starts
    assert episodes["episode_index"] == [0, 1] and episodes["length"] == data.episode_lengths.tolist()
    assert episodes["dataset_from_index"] == starts.tolist() and episodes["dataset_to_index"] == data.episode_ends.tolist()
    assert episodes["data/chunk_index"] == [0, 0] and episodes["data/file_index"] == [0, 0]
    assert episodes["tasks"] == [["Push the T-shaped block onto the T-shaped target."]] * 2
    action = data["action"].astype(np.float32).astype(np.float64)
    second = action[starts[1]:]
    np.testing.assert_allclose(episodes["stats/action/mean"][1], second.mean(0))
    np.testing.assert_allclose(episodes["stats/action/q50"][1], np.median(second, axis=0))
    stats = json.loads((folder / "meta" / "stats.json").read_text())
    np.testing.assert_allclose(stats["action"]["min"], action.min(0))
    np.testing.assert_allclose(stats["action"]["std"], action.std(0))
    np.testing.assert_allclose(stats["action"]["q99"], np.quantile(action, 0.99, axis=0))
    assert stats["action"]["count"] == [data.n_steps]
    image = np.asarray(stats["observation.image"]["mean"])
    assert image.shape == (3, 1, 1) and np.all((0 < image) & (image < 1))  # per channel, scaled to [0, 1]


@pytest.mark.parametrize("name,objects", [("transfer_cube", 7), ("insertion", 14)])
def test_arm_pair_folder_has_lerobots_aloha_features(name, objects, demos, exported):
    data = EpisodeDataset.load(demos[name])
    table, info = frames_of(exported[name])
    assert info["fps"] == 50 and info["robot_type"] == "aloha"
    features = info["features"]
    assert features["observation.state"]["names"]["motors"][:2] == ["left_waist", "left_shoulder"]
    assert features["observation.state"]["shape"] == [14] and features["action"]["shape"] == [14]
    assert features["observation.environment_state"]["shape"] == [objects]
    qpos = np.stack(table.column("observation.state").to_numpy(zero_copy_only=False))
    np.testing.assert_array_equal(qpos, data["qpos"].astype(np.float32))
    np.testing.assert_array_equal(table.column("next.reward").to_numpy(), data["stage"].astype(np.float32))
    np.testing.assert_array_equal(table.column("next.success").to_numpy(zero_copy_only=False), data["stage"] == 4)


def test_import_by_lerobots_conventions_rebuilds_the_states(demos, exported, tmp_path):
    """An export read as a foreign LeRobot set (--features): PushT states from the corners, the arm pair's qpos."""
    out = tmp_path / "pusht.npz"
    assert main(["import", "lerobot", str(exported["pusht_image"]), str(out),
                 "--features", "observation.state,observation.environment_state,observation.image"]) == 0
    data, back = EpisodeDataset.load(demos["pusht_image"]), EpisodeDataset.load(out)
    assert sorted(back.arrays) == ["action", "image", "state"] and back.meta["task"] == "pusht"
    np.testing.assert_array_equal(back["image"], data["image"])
    np.testing.assert_allclose(back["state"][:, :4], data["state"][:, :4], atol=1e-3)  # float32 columns
    turn = back["state"][:, 4] - data["state"][:, 4]
    np.testing.assert_allclose(np.angle(np.exp(1j * turn)), 0.0, atol=1e-5)  # the same pose; the angle up to 2 pi
    for a, b in zip(data.episode_starts, data.episode_ends, strict=True):
        assert np.ptp(turn[a:b]) < 1e-5  # unwrapped along the episode as the demonstrations are
    out = tmp_path / "cube.npz"
    assert main(["import", "lerobot", str(exported["transfer_cube"]), str(out), "--features",
                 "observation.state,observation.environment_state"]) == 0
    data, back = EpisodeDataset.load(demos["transfer_cube"]), EpisodeDataset.load(out)
    assert sorted(back.arrays) == ["action", "env_state", "qpos"] and back.meta["task"] == "transfer_cube"
    np.testing.assert_array_equal(back["qpos"], data["qpos"].astype(np.float32))
    out = tmp_path / "qpos.npz"
    assert main(["import", "lerobot", str(exported["insertion"]), str(out), "--features", "observation.state",
                 "--as", "insertion"]) == 0
    assert sorted(EpisodeDataset.load(out).arrays) == ["action", "qpos"]


def test_episodes_spread_over_several_files_come_back(demos, tmp_path, monkeypatch):
    monkeypatch.setattr(lerobot_format, "DATA_FILES_SIZE_MB", 1e-3)  # ~1 kB per file: one episode each
    assert main(["export", "lerobot", str(demos["pusht"]), str(tmp_path / "out")]) == 0
    files = sorted(p.relative_to(tmp_path / "out").as_posix() for p in (tmp_path / "out" / "data").glob("*/*"))
    assert files == ["data/chunk-000/file-000.parquet", "data/chunk-000/file-001.parquet"]
    episodes = pq.read_table(tmp_path / "out" / "meta" / "episodes" / "chunk-000" / "file-000.parquet")
    assert episodes.column("data/file_index").to_pylist() == [0, 1]
    assert main(["import", "lerobot", str(tmp_path / "out"), str(tmp_path / "back.npz")]) == 0
    assert_same(EpisodeDataset.load(demos["pusht"]), EpisodeDataset.load(tmp_path / "back.npz"))


def test_overwrite_replaces_an_earlier_export(demos, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["export", "lerobot", str(demos["transfer_cube"]), str(out)]) == 0
    assert main(["export", "lerobot", str(demos["pusht"]), str(out)]) == 2
    assert "already holds a coursekit LeRobot export; pass --overwrite" in capsys.readouterr().err
    assert main(["export", "lerobot", str(demos["pusht"]), str(out), "--overwrite", "--task", "Push the T."]) == 0
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["fps"] == 10 and pq.read_table(out / "meta" / "tasks.parquet").column("task").to_pylist() == ["Push the T."]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no staging folder left behind


@pytest.mark.usefixtures("one_torch_thread")
@pytest.mark.parametrize("name,policy,small", [("pusht", "diffusion", ["--down-dims", "16,32"]),
                                               ("transfer_cube", "act", ["--chunk-size", "10"])])
def test_training_on_the_imported_data_is_training_on_the_original(name, policy, small, demos, exported, tmp_path):
    assert main(["import", "lerobot", str(exported[name]), str(tmp_path / "back.npz")]) == 0
    losses, weights = [], []
    for data in (demos[name], tmp_path / "back.npz"):
        run = tmp_path / f"run{len(losses)}"
        assert main(["train", "--policy", policy, "--data", str(data), "--steps", "3", "--batch-size", "4", "--seed", "7",
                     "--warmup-steps", "1", "--out", str(run), "--threads", "1", "--no-progress", *small]) == 0
        losses.append([float(r["loss"]) for r in csv.DictReader((run / "metrics.csv").open())])
        weights.append(next(run.glob("*.safetensors")).read_bytes())
    assert losses[0] == losses[1] and weights[0] == weights[1]  # the same batches, gradients and weights at every step


def test_images_flag_renders_the_pusht_camera_frames(demos, tmp_path):
    """--images: observation.image = the env's 96 x 96 observation renders of the states; the .npz still comes back as it was."""
    from coursekit.envs.pusht_render import PushTRenderer

    out = tmp_path / "out"
    assert main(["export", "lerobot", str(demos["pusht"]), str(out), "--images"]) == 0
    _, info = frames_of(out)
    assert info["features"]["observation.image"]["shape"] == [96, 96, 3]
    data = EpisodeDataset.load(demos["pusht"])
    frames = read_folder(out).column("observation.image")  # PNG decoded
    renderer = PushTRenderer(96)
    for t in (0, 50, data.n_steps - 1):
        np.testing.assert_array_equal(frames[t], renderer.render(data["state"][t]))
    assert main(["import", "lerobot", str(out), str(tmp_path / "back.npz")]) == 0
    assert_same(data, EpisodeDataset.load(tmp_path / "back.npz"))
