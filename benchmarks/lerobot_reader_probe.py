"""Run INSIDE the lerobot venv (by ``benchmarks/check_lerobot_reader.py``): read folders with LeRobot's own loader.

    python lerobot_reader_probe.py OUT.npz FOLDER [FOLDER ...]

For each folder: ``LeRobotDataset(repo_id, root=FOLDER)`` (local, offline), then a torch
``DataLoader`` over it (batch 16, in order) for a few batches, and the same data set again
with ``delta_timestamps`` asking for an action chunk (LeRobot's padding at episode ends). Writes
what it saw to OUT.npz (keys ``<i>/<feature>``) and a JSON summary line to stdout. Imports only
lerobot and its dependencies, never coursekit.
"""

from __future__ import annotations

import json
import sys

import importlib.util
from pathlib import Path

import numpy as np
import torch


def _declare_torchvision_schemas_without_kernels() -> torch.library.Library | None:
    """Let ``import torchvision`` finish when its C++ ops cannot load; returns the library to keep alive.

    PyPI's torchvision 0.28 is built against the CUDA torch; beside the CPU torch 2.13.0 its
    ``_C`` extension does not load (it links libtorch_cuda), and ``torchvision._meta_registrations``
    then fails on its two unguarded ``register_fake`` calls (nms, qnms: "operator torchvision::nms
    does not exist"). Declaring those two schemas, with no kernels, lets the import complete.
    LeRobot's data set loader uses only torchvision's Python transforms, never these ops.
    """
    spec = importlib.util.find_spec("torchvision")
    compiled = next(Path(spec.submodule_search_locations[0]).glob("_C*.so"), None)
    try:
        torch.ops.load_library(str(compiled))
        return None
    except (OSError, TypeError):
        lib = torch.library.Library("torchvision", "DEF")  # noqa: TOR901
        lib.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        lib.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        return lib


_TORCHVISION_SCHEMAS = _declare_torchvision_schemas_without_kernels()

from lerobot.__version__ import __version__  # noqa: E402
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402

BATCHES, BATCH = 4, 16
CHUNK = 4
"""Frames of the action chunk asked for with delta_timestamps (t, t + 1/fps, ...)."""


def probe(i: int, root: str, out: dict[str, np.ndarray]) -> dict:
    ds = LeRobotDataset(f"coursekit/probe{i}", root=root)
    seen: dict[str, list[np.ndarray]] = {}
    loader = torch.utils.data.DataLoader(ds, batch_size=BATCH, shuffle=False, num_workers=0)
    for b, batch in enumerate(loader):
        if b == BATCHES:
            break
        for key, value in batch.items():
            if isinstance(value, torch.Tensor):
                seen.setdefault(key, []).append(value.numpy())
            elif key == "task":
                seen.setdefault(key, []).append(np.array(value))
    for key, parts in seen.items():
        out[f"{i}/{key}"] = np.concatenate(parts)
    chunked = LeRobotDataset(f"coursekit/probe{i}", root=root,
                             delta_timestamps={"action": [k / ds.fps for k in range(CHUNK)]})
    lengths = [int(ep["length"]) for ep in ds.meta.episodes]
    picks = [0, lengths[0] - 2, lengths[0] - 1, len(ds) - 1]  # inside, at and past the first episode's end
    out[f"{i}/chunk_picks"] = np.array(picks)
    out[f"{i}/chunk_action"] = np.stack([chunked[p]["action"].numpy() for p in picks])
    out[f"{i}/chunk_is_pad"] = np.stack([chunked[p]["action_is_pad"].numpy() for p in picks])
    return {"root": root, "len": len(ds), "num_episodes": ds.num_episodes, "fps": ds.fps,
            "episode_lengths": lengths, "camera_keys": ds.meta.camera_keys,
            "tasks": list(ds.meta.tasks.index), "stats_keys": sorted(ds.meta.stats)}


def main(argv: list[str]) -> int:
    out_path, roots = argv[0], argv[1:]
    out: dict[str, np.ndarray] = {}
    summary = {"lerobot": __version__, "torch": torch.__version__, "torchvision_ops_stubbed": _TORCHVISION_SCHEMAS is not None,
               "folders": [probe(i, root, out) for i, root in enumerate(roots)]}
    np.savez(out_path, **out)
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
