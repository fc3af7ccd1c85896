"""Demonstrations on disk: flat per-step arrays plus episode ends, with metadata.

Format (one ``.npz`` file, written atomically, read without pickle)::

    <key>         (N, ...)  every per-step array, episodes concatenated in order
                            (e.g. "obs" (N, Do), "action" (N, Da), "state" (N, Ds))
    episode_ends  (E,)      int64, exclusive end index of each episode: episode e is
                            rows episode_ends[e-1] : episode_ends[e]
    __meta__      ()        JSON text: format version, env id, obs type, expert, seed, ...

This is the flat layout of Diffusion Policy's replay buffer, without Zarr. The zip container
checksums every member, so a truncated or corrupt file is refused on load with a clear error.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coursekit.atomic import atomic_path
from coursekit.output_lock import OutputLock

FORMAT_VERSION = 1
_META_KEY = "__meta__"
_ENDS_KEY = "episode_ends"


class DatasetError(ValueError):
    """A dataset file that is missing, truncated, corrupt or inconsistent."""


@dataclass
class EpisodeDataset:
    """Per-step arrays of many episodes, concatenated, plus where each episode ends.

    Attributes:
        arrays: name -> array of shape (N, ...), N = total steps over all episodes.
        episode_ends: (E,) int64, exclusive end of each episode, strictly increasing, last == N.
        meta: JSON-serialisable metadata (env_id, obs_type, expert, seed, version, ...).
    """

    arrays: dict[str, np.ndarray]
    episode_ends: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.episode_ends = np.asarray(self.episode_ends, dtype=np.int64)
        ends = self.episode_ends
        if ends.ndim != 1:
            raise DatasetError(f"episode_ends must be 1-d, got shape {ends.shape}")
        if len(ends) and (ends[0] <= 0 or np.any(np.diff(ends) <= 0)):
            raise DatasetError(f"episode_ends must be strictly increasing and positive, got {ends[:10]}...")
        n = int(ends[-1]) if len(ends) else 0
        for key, arr in self.arrays.items():
            if key in (_META_KEY, _ENDS_KEY):
                raise DatasetError(f"array name {key!r} is reserved")
            if arr.shape[:1] != (n,):
                raise DatasetError(f"array {key!r} has {arr.shape[0] if arr.ndim else 0} rows, episode_ends says {n}")

    # ---- construction -------------------------------------------------------------------
    @classmethod
    def from_episodes(cls, episodes: list[dict[str, np.ndarray]], meta: dict[str, Any] | None = None) -> EpisodeDataset:
        """Concatenate a list of episodes (each: name -> (T_e, ...) array, same names in all)."""
        if not episodes:
            raise DatasetError("from_episodes needs at least one episode, got an empty list")
        keys = sorted(episodes[0])
        for i, ep in enumerate(episodes):
            if sorted(ep) != keys:
                raise DatasetError(f"episode {i} has arrays {sorted(ep)}, episode 0 has {keys}")
        lengths = [len(ep[keys[0]]) for ep in episodes]
        arrays = {k: np.concatenate([np.asarray(ep[k]) for ep in episodes], axis=0) for k in keys}
        return cls(arrays=arrays, episode_ends=np.cumsum(lengths), meta=dict(meta or {}))

    # ---- access -------------------------------------------------------------------------
    @property
    def n_episodes(self) -> int:
        return len(self.episode_ends)

    @property
    def n_steps(self) -> int:
        return int(self.episode_ends[-1]) if len(self.episode_ends) else 0

    @property
    def episode_starts(self) -> np.ndarray:
        """(E,) int64, inclusive start index of each episode."""
        return np.concatenate([[0], self.episode_ends[:-1]]).astype(np.int64)

    @property
    def episode_lengths(self) -> np.ndarray:
        """(E,) int64 steps per episode."""
        return np.diff(np.concatenate([[0], self.episode_ends])).astype(np.int64)

    def episode(self, index: int) -> dict[str, np.ndarray]:
        """The arrays of one episode, each (T_e, ...)."""
        if not -self.n_episodes <= index < self.n_episodes:
            raise IndexError(f"episode index {index} out of range for {self.n_episodes} episodes")
        index %= self.n_episodes
        start, end = int(self.episode_starts[index]), int(self.episode_ends[index])
        return {k: v[start:end] for k, v in self.arrays.items()}

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    def __repr__(self) -> str:
        shapes = ", ".join(f"{k}{tuple(v.shape)}" for k, v in self.arrays.items())
        return f"EpisodeDataset({self.n_episodes} episodes, {self.n_steps} steps: {shapes}; env={self.meta.get('env_id')})"

    # ---- disk ---------------------------------------------------------------------------
    def save(self, path: str | os.PathLike, lock: OutputLock | None = None) -> Path:
        """Write atomically to ``path`` (``.npz``); an existing file is replaced only on success.

        The write holds ``path``'s lock (``lock``, the caller's, or its own), which also removes
        the temporaries a killed earlier write of ``path`` left (see :mod:`coursekit.output_lock`).
        """
        path = Path(path)
        meta = {"format_version": FORMAT_VERSION, **self.meta}
        payload = {k: np.ascontiguousarray(v) for k, v in self.arrays.items()}
        payload[_ENDS_KEY] = self.episode_ends
        payload[_META_KEY] = np.array(json.dumps(meta, sort_keys=True))
        with atomic_path(path, lock=lock) as tmp:
            with open(tmp, "wb") as fh:  # a file handle: np.savez must not append ".npz"
                np.savez_compressed(fh, **payload)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> EpisodeDataset:
        """Read a dataset written by :meth:`save`; refuse anything else with one line saying what it is.

        Missing file, a directory, a ``.npy`` array, a zip that is not a dataset, an array of
        Python objects (never unpickled), ``__meta__`` that is not a JSON object, bad
        ``episode_ends``, a truncated or corrupt file: each raises a :class:`DatasetError`
        (``FileNotFoundError`` for a missing file) naming the path and the problem.
        """
        path = Path(path)
        where = repr(str(path))
        if path.is_dir():
            raise DatasetError(f"{where} is a directory, not a dataset file (.npz from `coursekit collect ...`)")
        if not path.is_file():
            raise FileNotFoundError(f"dataset file not found: {where} (make one with `coursekit collect ...`)")
        with open(path, "rb") as fh:
            magic = fh.read(6)
        if magic == b"\x93NUMPY":
            raise DatasetError(f"{where} is a single .npy array, not a coursekit dataset (an .npz of per-step "
                               f"arrays + {_ENDS_KEY!r} + {_META_KEY!r}, from `coursekit collect ...`)")
        if not magic.startswith(b"PK"):
            raise DatasetError(f"{where} is not a coursekit dataset: not an .npz (zip) file (starts with {magic!r})")
        try:
            _refuse_object_arrays(path)
            with np.load(path, allow_pickle=False) as npz:
                names = set(npz.files)
                if _META_KEY not in names or _ENDS_KEY not in names:
                    raise DatasetError(
                        f"{where} is not a coursekit dataset: it lacks {_META_KEY!r}/{_ENDS_KEY!r} "
                        f"(found {sorted(names)[:8]})"
                    )
                meta_text = npz[_META_KEY]
                ends = npz[_ENDS_KEY]
                arrays = {k: npz[k] for k in sorted(names - {_META_KEY, _ENDS_KEY})}
        except DatasetError:
            raise
        except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, KeyError, RuntimeError,
                NotImplementedError) as exc:  # zipfile: flipped flags read as encryption / unknown compression
            raise DatasetError(f"dataset file {where} is truncated or corrupt ({type(exc).__name__}: {exc})") from exc
        if meta_text.shape != () or meta_text.dtype.kind != "U":
            raise DatasetError(f"{where}: {_META_KEY!r} must be one JSON string, got a {meta_text.dtype} array of shape {meta_text.shape}")
        try:
            meta = json.loads(str(meta_text))
        except json.JSONDecodeError as exc:
            raise DatasetError(f"{where}: {_META_KEY!r} is not valid JSON ({exc})") from None
        if not isinstance(meta, dict):
            raise DatasetError(f"{where}: {_META_KEY!r} must be a JSON object (dict), got a {type(meta).__name__}: {str(meta_text)[:80]!r}")
        version = meta.get("format_version")
        if version != FORMAT_VERSION:
            raise DatasetError(f"{where} has format_version {version!r}; this coursekit reads {FORMAT_VERSION}")
        if ends.dtype.kind not in "iu":
            raise DatasetError(f"{where}: {_ENDS_KEY!r} must hold integers, got dtype {ends.dtype}")
        try:
            return cls(arrays=arrays, episode_ends=ends, meta=meta)
        except DatasetError as exc:
            raise DatasetError(f"{where}: {exc}") from None


def _refuse_object_arrays(path: Path) -> None:
    """Read each member's .npy header (not its data) and refuse dtype object: loading it would unpickle."""
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            if not info.filename.endswith(".npy"):
                continue
            with zf.open(info) as member:
                version = np.lib.format.read_magic(member)
                read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
                _, _, dtype = read_header(member)
            if dtype.hasobject:
                raise DatasetError(f"{str(path)!r}: array {info.filename[:-4]!r} holds Python objects (dtype {dtype}); "
                                   f"coursekit never unpickles data, so this is not a dataset it can read")


def is_dataset_file(path: str | os.PathLike) -> bool:
    """True if ``path`` is an .npz with the members every coursekit dataset has (only the zip index is read)."""
    try:
        with zipfile.ZipFile(path) as zf:
            return {f"{_META_KEY}.npy", f"{_ENDS_KEY}.npy"} <= set(zf.namelist())
    except (OSError, zipfile.BadZipFile, ValueError, RuntimeError, NotImplementedError):
        return False


def dataset_foreign(path: str | os.PathLike) -> str | None:
    """None if the file ``path`` is a coursekit dataset, else why not (``coursekit.outputs.check_output``'s ``foreign``)."""
    return None if is_dataset_file(path) else "it lacks the members every coursekit dataset has"
