"""LeRobotDataset v3.0 on disk: the folder layout, written and read with pyarrow.

LeRobot's exchange format (https://huggingface.co/docs/lerobot/lerobot-dataset-v3) is a folder::

    meta/info.json           codebase_version "v3.0", fps, features {key: {dtype, shape, names}},
                             total_episodes / total_frames / total_tasks, splits, chunks_size,
                             data_files_size_in_mb / video_files_size_in_mb, data_path / video_path
    meta/stats.json          per feature: min, max, mean, std, count, q01, q10, q50, q90, q99
    meta/tasks.parquet       task_index (int64) with the task text as the (pandas) index "task"
    meta/episodes/chunk-000/file-000.parquet
                             one row per episode: episode_index, tasks, length, dataset_from_index,
                             dataset_to_index, data/chunk_index, data/file_index,
                             meta/episodes/chunk_index, meta/episodes/file_index, stats/<key>/<stat>
    data/chunk-CCC/file-FFF.parquet
                             one row per frame, one column per feature; whole episodes per file,
                             a new file past data_files_size_in_mb, a new chunk every chunks_size files
    videos/<key>/chunk-CCC/file-FFF.mp4   "video" features (coursekit writes "image" features instead)

Every frame has the five index columns ``episode_index``, ``frame_index``, ``timestamp``
(= frame_index / fps, float32), ``index`` (0..N-1 over the whole set) and ``task_index``.
Column types are those HF ``datasets`` derives from info.json, through which LeRobot reads the
frames: shape (1,) -> a plain column; shape (d,) -> fixed_size_list<d>; dtype "image" ->
struct{bytes, path} holding a PNG (lossless, so uint8 frames come back exactly).

:func:`write_folder` writes a :class:`Frames` into an empty folder; ``coursekit.data.lerobot_reader``
reads and checks one.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from coursekit.data.lerobot_stats import episode_stats_columns, feature_stats, stats_to_json

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000
"""Files per chunk folder (LeRobot's default)."""
DATA_FILES_SIZE_MB = 100
"""A data file is closed once it holds this many megabytes (LeRobot's default)."""
VIDEO_FILES_SIZE_MB = 200
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
INFO, STATS, TASKS = "meta/info.json", "meta/stats.json", "meta/tasks.parquet"
INDEX_KEYS = ("timestamp", "frame_index", "episode_index", "index", "task_index")
"""The columns every LeRobot frame has; :func:`write_folder` makes them from the episode ends and fps."""


@dataclass(frozen=True)
class Feature:
    """One feature of info.json: what one frame holds under this key."""

    dtype: str
    """A numpy dtype name ('float32', 'int64', 'bool', ...), or 'image' (uint8 H x W x 3) or 'video'."""
    shape: tuple[int, ...]
    """Per-frame shape: (1,) for a scalar, (d,) for a vector, (H, W, 3) for an image."""
    names: Any = None
    """Label of each dimension (a list, or a dict of lists as in LeRobot's own sets), or None."""

    def __post_init__(self) -> None:
        if not self.shape or any(not isinstance(n, int) or n < 1 for n in self.shape):
            raise ValueError(f"feature shape must be positive ints, got {self.shape!r}")
        if self.dtype not in ("image", "video"):
            np.dtype(self.dtype)  # TypeError for a name numpy does not know
        elif len(self.shape) != 3 or self.shape[2] != 3:
            raise ValueError(f"an {self.dtype} feature must have shape (H, W, 3), got {self.shape!r}")

    def to_json(self) -> dict[str, Any]:
        return {"dtype": self.dtype, "shape": list(self.shape), "names": self.names}


def _index_features() -> dict[str, Feature]:
    return {"timestamp": Feature("float32", (1,)), "frame_index": Feature("int64", (1,)),
            "episode_index": Feature("int64", (1,)), "index": Feature("int64", (1,)), "task_index": Feature("int64", (1,))}


@dataclass
class Frames:
    """A data set to write: per-frame columns, episode ends, rate and tasks.

    columns: feature key -> (N, *shape) array ((N,) for shape (1,); (N, H, W, 3) uint8 for images).
    features: the same keys -> :class:`Feature` (the index columns are added by the writer).
    episode_ends: (E,) int, exclusive end of each episode (as ``EpisodeDataset``).
    """

    columns: dict[str, np.ndarray]
    features: dict[str, Feature]
    episode_ends: np.ndarray
    fps: int
    tasks: tuple[str, ...] = ("",)
    episode_tasks: np.ndarray | None = None
    """(E,) index into ``tasks`` per episode (None: task 0 everywhere)."""
    robot_type: str | None = None

    def __post_init__(self) -> None:
        self.episode_ends = np.asarray(self.episode_ends, dtype=np.int64)
        n = int(self.episode_ends[-1]) if len(self.episode_ends) else 0
        if set(self.columns) != set(self.features):
            raise ValueError(f"columns {sorted(self.columns)} and features {sorted(self.features)} differ")
        for key, values in self.columns.items():
            spec = self.features[key]
            want = (n,) if spec.shape == (1,) else (n, *spec.shape)
            if key in INDEX_KEYS or "/" in key:
                raise ValueError(f"feature name {key!r} is reserved or holds '/' (LeRobot refuses both)")
            if values.shape != want:
                raise ValueError(f"feature {key!r}: {values.shape[0] if values.ndim else 0} frames of shape "
                                 f"{values.shape[1:]}, expected {want} ({n} frames of {spec.shape})")
        if self.episode_tasks is None:
            self.episode_tasks = np.zeros(len(self.episode_ends), dtype=np.int64)


# ---- writing -------------------------------------------------------------------------------
def _arrow_column(values: np.ndarray, spec: Feature) -> pa.Array:
    """(N, *shape) values -> the arrow column HF datasets expects for ``spec``."""
    if spec.dtype == "image":
        from PIL import Image

        pngs = []
        for frame in values:
            buf = io.BytesIO()
            Image.fromarray(np.ascontiguousarray(frame, dtype=np.uint8)).save(buf, format="PNG")
            pngs.append(buf.getvalue())
        return pa.StructArray.from_arrays([pa.array(pngs, pa.binary()), pa.nulls(len(pngs), pa.string())],
                                          names=["bytes", "path"])
    flat = pa.array(np.ascontiguousarray(values, dtype=spec.dtype).reshape(-1))
    return flat if spec.shape == (1,) else pa.FixedSizeListArray.from_arrays(flat, spec.shape[0])


def _index_columns(frames: Frames) -> dict[str, np.ndarray]:
    lengths = np.diff(np.concatenate([[0], frames.episode_ends]))
    episode = np.repeat(np.arange(len(lengths), dtype=np.int64), lengths)  # (N,)
    frame = np.arange(len(episode), dtype=np.int64) - np.repeat(frames.episode_ends - lengths, lengths)  # (N,)
    return {"timestamp": (frame / frames.fps).astype(np.float32), "frame_index": frame, "episode_index": episode,
            "index": np.arange(len(episode), dtype=np.int64),
            "task_index": np.repeat(np.asarray(frames.episode_tasks, dtype=np.int64), lengths)}


def _file_of_each_episode(sizes: np.ndarray) -> np.ndarray:
    """(E,) running file number: whole episodes, a new file once one holds DATA_FILES_SIZE_MB."""
    files, current, used = [], 0, 0.0
    for size in sizes:
        if used and used + size > DATA_FILES_SIZE_MB * 2**20:
            current, used = current + 1, 0.0
        files.append(current)
        used += size
    return np.asarray(files, dtype=np.int64)


def _pandas_index_metadata(index: str, columns: dict[str, str]) -> bytes:
    """The "pandas" schema metadata that makes ``pandas.read_parquet`` use column ``index`` as the index.

    Spec: pandas' developer guide, "Storing pandas DataFrame objects in Apache Parquet format"
    (LeRobot reads tasks.parquet with pandas and looks tasks up by that index).
    """
    described = [{"name": name, "field_name": name, "pandas_type": kind, "numpy_type": "object" if kind == "unicode" else kind,
                  "metadata": None} for name, kind in columns.items()]
    column_index = {"name": None, "field_name": None, "pandas_type": "unicode", "numpy_type": "object",
                    "metadata": {"encoding": "UTF-8"}}
    return json.dumps({"index_columns": [index], "column_indexes": [column_index], "columns": described,
                       "creator": {"library": "pyarrow", "version": pa.__version__}, "pandas_version": "2.2.0"}).encode()


def _write_tasks(root: Path, tasks: tuple[str, ...]) -> None:
    schema = pa.schema([("task_index", pa.int64()), ("task", pa.string())],
                       metadata={b"pandas": _pandas_index_metadata("task", {"task_index": "int64", "task": "unicode"})})
    pq.write_table(pa.table({"task_index": np.arange(len(tasks), dtype=np.int64), "task": list(tasks)}, schema=schema),
                   root / TASKS)


def write_folder(root: str | Path, frames: Frames) -> dict[str, Any]:
    """Write ``frames`` as a LeRobotDataset v3.0 into the empty folder ``root``; returns info.json's content."""
    root = Path(root)
    features = {**frames.features, **_index_features()}
    columns = {**frames.columns, **_index_columns(frames)}
    arrow = {key: _arrow_column(values, features[key]) for key, values in columns.items()}
    ends, starts = frames.episode_ends, np.concatenate([[0], frames.episode_ends[:-1]])
    per_frame = sum(a.nbytes for a in arrow.values()) / max(len(columns["index"]), 1)
    file_no = _file_of_each_episode((ends - starts) * per_frame)
    for f in np.unique(file_no):
        rows = np.flatnonzero(np.isin(columns["episode_index"], np.flatnonzero(file_no == f)))
        path = root / DATA_PATH.format(chunk_index=int(f) // CHUNKS_SIZE, file_index=int(f) % CHUNKS_SIZE)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table({k: a.take(pa.array(rows)) for k, a in arrow.items()}), path)
    episodes: dict[str, Any] = {
        "episode_index": np.arange(len(ends), dtype=np.int64),
        "tasks": [[frames.tasks[int(t)]] for t in frames.episode_tasks],
        "length": ends - starts, "dataset_from_index": starts.astype(np.int64), "dataset_to_index": ends,
        "data/chunk_index": file_no // CHUNKS_SIZE, "data/file_index": file_no % CHUNKS_SIZE,
        "meta/episodes/chunk_index": np.zeros(len(ends), np.int64), "meta/episodes/file_index": np.zeros(len(ends), np.int64),
    }
    for key, values in columns.items():
        episodes.update(episode_stats_columns(key, values, starts, ends, image=features[key].dtype == "image"))
    (root / EPISODES_PATH.format(chunk_index=0, file_index=0)).parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.table(episodes), root / EPISODES_PATH.format(chunk_index=0, file_index=0))
    _write_tasks(root, frames.tasks)
    stats = {key: feature_stats(values, image=features[key].dtype == "image") for key, values in columns.items()}
    (root / STATS).write_text(json.dumps(stats_to_json(stats), indent=2))
    info = {
        "codebase_version": CODEBASE_VERSION, "robot_type": frames.robot_type,
        "total_episodes": len(ends), "total_frames": int(ends[-1]) if len(ends) else 0, "total_tasks": len(frames.tasks),
        "chunks_size": CHUNKS_SIZE, "data_files_size_in_mb": DATA_FILES_SIZE_MB,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_MB, "fps": int(frames.fps), "splits": {"train": f"0:{len(ends)}"},
        "data_path": DATA_PATH, "video_path": None, "features": {k: f.to_json() for k, f in features.items()},
    }
    (root / INFO).write_text(json.dumps(info, indent=4))
    return info

