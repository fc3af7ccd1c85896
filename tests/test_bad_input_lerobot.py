"""`coursekit export lerobot` / `coursekit import lerobot` on bad input: ONE line naming the bad value, exit 2, nothing written.

The output area holds a user's notes and results folder, real demonstrations, a good export,
and LeRobot folders each broken in one way (not v3.0, a feature's column missing, lengths that
disagree, a NaN action, an fps other than the task's, no way to tell the task). Every case must
leave every file byte-identical and add nothing.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

pytest.importorskip("mujoco")

from cli_refusals import assert_refused_in_one_line
from coursekit.cli import main  # noqa: E402
from coursekit.data.episodes import EpisodeDataset  # noqa: E402

DATA = "data/chunk-000/file-000.parquet"
EPISODES = "meta/episodes/chunk-000/file-000.parquet"


def _edit_info(folder: Path, **changes) -> None:
    info = json.loads((folder / "meta" / "info.json").read_text())
    info.update(changes)
    (folder / "meta" / "info.json").write_text(json.dumps(info))


def _set_column(folder: Path, relative: str, name: str, values) -> None:
    table = pq.read_table(folder / relative)
    pq.write_table(table.set_column(table.column_names.index(name), name, pa.array(values, table.schema.field(name).type)),
                   folder / relative)


def _foreign(folder: Path) -> Path:
    """An export without coursekit's record: read by LeRobot's conventions, as a LeRobot set would be."""
    (folder / "meta" / "coursekit.json").unlink()
    return folder


@pytest.fixture(scope="module")
def originals(tmp_path_factory):
    from coursekit.experts.pusht_planner import collect_dataset

    root = tmp_path_factory.mktemp("originals")
    collect_dataset(2, 0, progress=False).save(root / "demos.npz")
    rng = np.random.default_rng(0)  # a short synthetic arm-pair set: these cases test the checks, not the expert
    arm = {"qpos": rng.normal(size=(30, 14)), "action": rng.normal(size=(30, 14)), "env_state": rng.normal(size=(30, 7))}
    EpisodeDataset(arm, [12, 30], {"task": "transfer_cube", "env_id": "coursekit/AlohaTransferCube-v0"}).save(root / "arm.npz")
    nan = EpisodeDataset.load(root / "demos.npz")
    nan.arrays["action"] = nan["action"].copy()
    nan.arrays["action"][3, 1] = np.nan
    nan.save(root / "nan.npz")
    EpisodeDataset({"state": nan["state"]}, nan.episode_ends, nan.meta).save(root / "noaction.npz")
    assert main(["export", "lerobot", str(root / "demos.npz"), str(root / "good")]) == 0
    assert main(["export", "lerobot", str(root / "arm.npz"), str(root / "armgood")]) == 0
    broken = {name: root / name for name in ("v21", "nocolumn", "frames", "lengths", "nanact", "fps20", "armnotask")}
    for name, folder in broken.items():
        shutil.copytree(root / ("armgood" if name == "armnotask" else "good"), folder)
    _edit_info(broken["v21"], codebase_version="v2.1")
    table = pq.read_table(broken["nocolumn"] / DATA)
    pq.write_table(table.drop_columns(["coursekit.state"]), broken["nocolumn"] / DATA)
    _edit_info(broken["frames"], total_frames=171)
    lengths = pq.read_table(broken["lengths"] / EPISODES).column("length").to_pylist()
    _set_column(broken["lengths"], EPISODES, "length", [lengths[0] + 1, *lengths[1:]])
    action = pq.read_table(broken["nanact"] / DATA).column("action").to_pylist()
    action[5] = [float("nan"), action[5][1]]
    _set_column(_foreign(broken["nanact"]), DATA, "action", action)
    frame = pq.read_table(broken["fps20"] / DATA).column("frame_index").to_numpy()
    _set_column(broken["fps20"], DATA, "timestamp", (frame / 20).astype(np.float32))
    _edit_info(broken["fps20"], fps=20)
    info = json.loads((broken["armnotask"] / "meta" / "info.json").read_text())
    del info["features"]["observation.environment_state"]
    (broken["armnotask"] / "meta" / "info.json").write_text(json.dumps(info))
    _foreign(broken["armnotask"])
    return root


@pytest.fixture
def area(tmp_path, originals):
    (tmp_path / "notes.txt").write_text("my notes\n")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "table.csv").write_text("a,b\n1,2\n")
    for entry in originals.iterdir():
        (shutil.copytree if entry.is_dir() else shutil.copy)(entry, tmp_path / entry.name)
    return tmp_path




CASES = [
    # export: output path (checked before any work), input, rate, actions
    ("export lerobot {A}/demos.npz {A}/results", "OUT_DIR '{A}/results' exists and is not a coursekit LeRobot export (it holds table.csv)"),
    ("export lerobot {A}/demos.npz {A}/results --overwrite", "is not a coursekit LeRobot export"),
    ("export lerobot {A}/demos.npz {A}/notes.txt", "OUT_DIR '{A}/notes.txt' exists and is a file"),
    ("export lerobot {A}/demos.npz {A}/good", "OUT_DIR '{A}/good' already holds a coursekit LeRobot export; pass --overwrite"),
    ("export lerobot {A}/demos.npz {A}/demos.npz/out", "is inside the input '{A}/demos.npz'"),
    ("export lerobot {A}/demos.npz {A}", "OUT_DIR '{A}' contains the input '{A}/demos.npz'"),
    ("export lerobot {A}/missing.npz {A}/out", "dataset file not found: '{A}/missing.npz'"),
    ("export lerobot {A}/notes.txt {A}/out", "'{A}/notes.txt' is not a coursekit dataset"),
    ("export lerobot {A}/demos.npz {A}/out --fps 20", "--fps 20 is not the pusht control rate, 10 Hz"),
    ("export lerobot {A}/arm.npz {A}/out --fps 10", "--fps 10 is not the transfer_cube control rate, 50 Hz"),
    ("export lerobot {A}/demos.npz {A}/out --fps 0", "argument --fps: must be an integer >= 1, got '0'"),
    ("export lerobot {A}/nan.npz {A}/out", "the data set's action of step 3 (episode 0) is [" ),
    ("export lerobot {A}/noaction.npz {A}/out", "the data set has no 'action' array (it has ['state'])"),
    ("export lerobot {A}/arm.npz {A}/out --images", "rendering images from states is for PushT; these are transfer_cube"),
    ("export lerobot {A}/demos.npz {A}/out --task", "argument --task: expected one argument"),
    ("export csv {A}/demos.npz {A}/out", "invalid choice: 'csv'"),
    ("export", "the following arguments are required: FORMAT"),
    # import: output path, then the folder: not v3, missing features, lengths, NaN actions, rate, task
    ("import lerobot {A}/good {A}/notes.txt", "OUT '{A}/notes.txt' exists and is not a coursekit dataset"),
    ("import lerobot {A}/good {A}/demos.npz", "OUT '{A}/demos.npz' already holds a coursekit dataset; pass --overwrite"),
    ("import lerobot {A}/good {A}/good/back.npz", "is inside the input '{A}/good'"),
    ("import lerobot {A}/good {A}/results", "OUT '{A}/results' is a directory"),
    ("import lerobot {A}/results {A}/out.npz", "'{A}/results' is not a LeRobotDataset folder: it has no meta/info.json"),
    ("import lerobot {A}/missing {A}/out.npz", "'{A}/missing' is not a folder"),
    ("import lerobot {A}/v21 {A}/out.npz", "LeRobot folder '{A}/v21' is LeRobot format 'v2.1'; coursekit reads 'v3.0'"),
    ("import lerobot {A}/nocolumn {A}/out.npz", "data/chunk-000/file-000.parquet lacks the column(s) ['coursekit.state']"),
    ("import lerobot {A}/good {A}/out.npz --features observation.velocity",
     "--features names 'observation.velocity', which '{A}/good' does not have"),
    ("import lerobot {A}/good {A}/out.npz --features observation.state",
     "missing from the import: ['observation.environment_state']"),
    ("import lerobot {A}/good {A}/out.npz --features next.reward", "--features 'next.reward' has no coursekit counterpart"),
    ("import lerobot {A}/good {A}/out.npz --features observation.state,,action", "argument --features: must be comma-separated"),
    ("import lerobot {A}/frames {A}/out.npz", "meta/info.json says total_frames = 171, the data holds 170"),
    ("import lerobot {A}/lengths {A}/out.npz", "meta/episodes says episode 0 is frames"),
    ("import lerobot {A}/nanact {A}/out.npz", "the action of frame 5 (episode 0) is [nan,"),
    ("import lerobot {A}/fps20 {A}/out.npz", "runs at 20 fps, but pusht is controlled at 10 Hz"),
    ("import lerobot {A}/armnotask {A}/out.npz", "no object poses to tell the task by; say which with --as"),
    ("import lerobot {A}/good {A}/out.npz --as cube", "argument --as: invalid choice: 'cube'"),
    ("import lerobot {A}/good {A}/out.npz --as transfer_cube", "transfer_cube takes 14-d actions"),
]


@pytest.mark.parametrize("line,expected", CASES, ids=[c[0].replace("{A}/", "")[:60] for c in CASES])
def test_bad_input_is_one_clear_line_and_touches_nothing(area, capsys, line, expected):
    assert_refused_in_one_line(main, [a.replace("{A}", str(area)) for a in line.split()], area, expected, capsys)


def test_the_broken_folders_differ_from_a_good_one_only_where_intended(area, tmp_path):
    """Control: the good export and the arm-pair export import fine, so each case above fails for its own reason."""
    assert main(["import", "lerobot", str(area / "good"), str(tmp_path / "a.npz")]) == 0
    assert main(["import", "lerobot", str(area / "armgood"), str(tmp_path / "b.npz")]) == 0
    assert main(["import", "lerobot", str(area / "armnotask"), str(tmp_path / "c.npz"), "--as", "transfer_cube"]) == 0
