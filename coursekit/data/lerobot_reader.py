"""Reading a LeRobotDataset v3.0 folder (layout: ``coursekit.data.lerobot_format``), checked as it is read.

:func:`read_folder` opens a folder and checks that it is one consistent v3.0 set before any frame
is decoded: info.json is v3.0 with a whole-number fps and well-formed features; every declared
(non-video) feature is a column of every data file; ``index`` runs 0..N-1; each episode's frames
are contiguous and count 0, 1, 2, ...; timestamps are frame_index / fps; meta/episodes agrees
with the data on every episode's first frame, end and length; info.json's totals match; every
task_index is listed in meta/tasks.parquet. Each failure is a ``ValueError`` naming the folder,
the file and the value. :meth:`LeRobotFolder.column` then decodes one feature.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from coursekit.data.lerobot_format import CODEBASE_VERSION, INDEX_KEYS, INFO, TASKS, Feature


@dataclass
class LeRobotFolder:
    """A checked LeRobotDataset v3.0 folder: info, features, episode bounds and tasks; frames on demand.

    ``episode_ends`` (E,) are in frame order (frames sorted by ``index``); ``episode_tasks`` (E,)
    index ``tasks``. :meth:`column` decodes one feature into (N, *shape) (images (N, H, W, 3) uint8).
    """

    root: Path
    info: dict[str, Any]
    features: dict[str, Feature]
    episode_ends: np.ndarray
    tasks: tuple[str, ...]
    episode_tasks: np.ndarray
    table: pa.Table = field(repr=False)

    @property
    def fps(self) -> int:
        return int(self.info["fps"])

    def column(self, key: str) -> np.ndarray:
        """Feature ``key`` of every frame, (N, *shape) with the dtype info.json declares."""
        if key not in self.features:
            raise ValueError(f"{_where(self.root)} has no feature {key!r} (it has {sorted(self.features)})")
        spec = self.features[key]
        if spec.dtype == "video":
            raise ValueError(f"{_where(self.root)}: feature {key!r} is stored as mp4 video; coursekit reads parquet frames "
                             f"and 'image' features, not video (leave it out with --features)")
        arr = self.table.column(key).combine_chunks()
        if arr.null_count:
            raise ValueError(f"{_where(self.root)}: feature {key!r} is missing (null) in {arr.null_count} frames")
        return _image_column(self.root, key, arr, spec) if spec.dtype == "image" else _array_column(self.root, key, arr, spec)


def _where(root: Path) -> str:
    return f"LeRobot folder {str(root)!r}"


def _array_column(root: Path, key: str, arr: pa.Array, spec: Feature) -> np.ndarray:
    n, width = len(arr), int(np.prod(spec.shape))
    if pa.types.is_list(arr.type) or pa.types.is_large_list(arr.type) or pa.types.is_fixed_size_list(arr.type):
        lengths = arr.value_lengths().to_numpy(zero_copy_only=False) if not pa.types.is_fixed_size_list(arr.type) \
            else np.full(n, arr.type.list_size)
        if np.any(lengths != width):
            bad = int(np.flatnonzero(lengths != width)[0])
            raise ValueError(f"{_where(root)}: feature {key!r} has {int(lengths[bad])} values in frame {bad}, "
                             f"info.json declares shape {list(spec.shape)}")
        arr = arr.flatten()
    elif width != 1:
        raise ValueError(f"{_where(root)}: feature {key!r} holds one value per frame, info.json declares shape {list(spec.shape)}")
    values = arr.to_numpy(zero_copy_only=False).astype(spec.dtype)
    return values.reshape(n) if spec.shape == (1,) else values.reshape(n, *spec.shape)


def _image_column(root: Path, key: str, arr: pa.Array, spec: Feature) -> np.ndarray:
    from PIL import Image

    if not pa.types.is_struct(arr.type) or arr.type.get_field_index("bytes") < 0:
        raise ValueError(f"{_where(root)}: image feature {key!r} is a {arr.type} column, not struct{{bytes, path}}")
    data = arr.field("bytes")
    if data.null_count:
        raise ValueError(f"{_where(root)}: image feature {key!r} refers to image files instead of holding the images "
                         f"({data.null_count} frames); coursekit reads embedded images only")
    frames = np.stack([np.asarray(Image.open(io.BytesIO(b)).convert("RGB")) for b in data.to_pylist()])
    if frames.shape[1:] != spec.shape:
        raise ValueError(f"{_where(root)}: image feature {key!r} holds {frames.shape[1:]} images, info.json declares "
                         f"{tuple(spec.shape)}")
    return frames


def _read_info(root: Path) -> tuple[dict[str, Any], dict[str, Feature]]:
    if not root.is_dir():
        raise ValueError(f"{str(root)!r} is not a folder (a LeRobotDataset is a folder with meta/info.json)")
    if not (root / INFO).is_file():
        raise ValueError(f"{str(root)!r} is not a LeRobotDataset folder: it has no {INFO}")
    try:
        info = json.loads((root / INFO).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{_where(root)}: {INFO} is not valid JSON ({exc})") from None
    if not isinstance(info, dict) or not isinstance(info.get("features"), dict):
        raise ValueError(f"{_where(root)}: {INFO} is not a JSON object with a 'features' object")
    version = info.get("codebase_version")
    if version != CODEBASE_VERSION:
        raise ValueError(f"{_where(root)} is LeRobot format {version!r}; coursekit reads {CODEBASE_VERSION!r} "
                         f"(convert older sets with LeRobot's convert_dataset_v21_to_v30)")
    fps = info.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or fps <= 0 or fps != int(fps):
        raise ValueError(f"{_where(root)}: fps must be a positive whole number of frames per second, got {fps!r}")
    features = {}
    for key, spec in info["features"].items():
        try:
            features[key] = Feature(str(spec["dtype"]), tuple(spec["shape"]), spec.get("names"))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{_where(root)}: feature {key!r} in {INFO} is not a {{dtype, shape, names}} entry ({exc})") from None
    missing = [k for k in INDEX_KEYS if k not in features]
    if missing:
        raise ValueError(f"{_where(root)}: {INFO} lacks the index feature(s) {missing} every LeRobot frame has")
    return info, features


def _read_parquets(root: Path, folder: str, columns: list[str] | None = None) -> pa.Table:
    paths = sorted((root / folder).glob("*/*.parquet"))
    if not paths:
        raise ValueError(f"{_where(root)} has no {folder}/chunk-*/file-*.parquet files (not a v3.0 set?)")
    tables = []
    for path in paths:
        table = pq.read_table(path)
        absent = [c for c in columns or [] if c not in table.column_names]
        if absent:
            raise ValueError(f"{_where(root)}: {path.relative_to(root)} lacks the column(s) {absent} that {INFO} declares")
        tables.append(table.select(columns) if columns else table)
    try:
        return pa.concat_tables(tables, promote_options="permissive")
    except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
        raise ValueError(f"{_where(root)}: the {folder} files disagree on their columns ({exc})") from None


def _episode_bounds(root: Path, table: pa.Table, fps: int) -> np.ndarray:
    """(E,) ends of the episodes of the frame table (sorted by index), after checking the index columns."""
    n = table.num_rows
    if not np.array_equal(table.column("index").to_numpy(), np.arange(n)):
        raise ValueError(f"{_where(root)}: the 'index' column is not 0..{n - 1} over the {n} frames")
    episode = table.column("episode_index").to_numpy()
    ends = np.append(np.flatnonzero(np.diff(episode) != 0) + 1, n).astype(np.int64)
    if len(np.unique(episode)) != len(ends):
        raise ValueError(f"{_where(root)}: the frames of an episode are not contiguous in 'index' order")
    starts = np.concatenate([[0], ends[:-1]])
    frame = table.column("frame_index").to_numpy()
    expected = np.arange(n) - np.repeat(starts, ends - starts)
    if not np.array_equal(frame, expected):
        bad = int(np.flatnonzero(frame != expected)[0])
        raise ValueError(f"{_where(root)}: frame_index {int(frame[bad])} at index {bad}, expected {int(expected[bad])} "
                         f"(frames of an episode must count 0, 1, 2, ...)")
    timestamp = table.column("timestamp").to_numpy().astype(np.float64)
    off = np.abs(timestamp - expected / fps) > 1e-4
    if np.any(off):
        bad = int(np.flatnonzero(off)[0])
        raise ValueError(f"{_where(root)}: timestamp {timestamp[bad]:.6g} s at index {bad} is not frame_index / fps = "
                         f"{expected[bad] / fps:.6g} s (fps {fps})")
    return ends


def _check_episodes(root: Path, info: dict[str, Any], table: pa.Table, ends: np.ndarray) -> None:
    episodes = _read_parquets(root, "meta/episodes", ["episode_index", "length", "dataset_from_index", "dataset_to_index"])
    rows = {int(e): (int(a), int(b), int(n)) for e, a, b, n in zip(
        *(episodes.column(c).to_numpy() for c in ("episode_index", "dataset_from_index", "dataset_to_index", "length")), strict=True)}
    starts = np.concatenate([[0], ends[:-1]])
    ids = table.column("episode_index").to_numpy()[starts]
    for e, a, b in zip(ids, starts, ends, strict=True):
        if rows.get(int(e)) != (int(a), int(b), int(b - a)):
            raise ValueError(f"{_where(root)}: meta/episodes says episode {int(e)} is frames {rows.get(int(e))} "
                             f"(from, to, length); the data holds frames ({int(a)}, {int(b)}, {int(b - a)})")
    for name, value in (("total_frames", table.num_rows), ("total_episodes", len(ends))):
        if info.get(name) != value:
            raise ValueError(f"{_where(root)}: {INFO} says {name} = {info.get(name)!r}, the data holds {value}")


def _read_tasks(root: Path) -> dict[int, str]:
    if not (root / TASKS).is_file():
        raise ValueError(f"{_where(root)} has no {TASKS}")
    table = pq.read_table(root / TASKS)
    pandas_meta = json.loads((table.schema.metadata or {}).get(b"pandas", b"{}"))
    named = [c for c in pandas_meta.get("index_columns", []) if isinstance(c, str)]
    text = next((c for c in [*named, "task", "__index_level_0__"] if c in table.column_names), None)
    if text is None or "task_index" not in table.column_names:
        raise ValueError(f"{_where(root)}: {TASKS} has columns {table.column_names}, not task_index and the task text")
    return dict(zip(table.column("task_index").to_pylist(), table.column(text).to_pylist(), strict=True))


def read_folder(root: str | Path) -> LeRobotFolder:
    """Open and check a LeRobotDataset v3.0 folder (info, episodes, tasks, index columns); frames stay as parquet."""
    root = Path(root)
    info, features = _read_info(root)
    stored = [k for k, f in features.items() if f.dtype != "video"]
    table = _read_parquets(root, "data", stored)
    table = table.take(pc.sort_indices(table, [("index", "ascending")]))
    ends = _episode_bounds(root, table, int(info["fps"]))
    _check_episodes(root, info, table, ends)
    task_text = _read_tasks(root)
    frame_tasks = table.column("task_index").to_numpy()[np.concatenate([[0], ends[:-1]])]
    unknown = sorted(set(frame_tasks.tolist()) - set(task_text))
    if unknown:
        raise ValueError(f"{_where(root)}: frames use task_index {unknown}, which {TASKS} does not list")
    order = sorted(task_text)
    return LeRobotFolder(root, info, features, ends, tuple(task_text[i] for i in order),
                         np.array([order.index(int(t)) for t in frame_tasks], dtype=np.int64), table)
