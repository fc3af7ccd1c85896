"""Our LeRobot export, read by LeRobot's own ``LeRobotDataset``: the real-reader check (not CI, not a test).

Run: ``.venv/bin/python -m benchmarks.check_lerobot_reader`` (needs PyPI once, ~1.5 GB of packages).

1. A separate venv under ``~/.cache/coursekit/lerobot-check/`` (never in the repository) gets
   the ``lerobot`` package from PyPI with torch pinned to 2.13.0, the CPU wheel this machine has.
   lerobot 0.4.4 declares torch<2.11, which would pull a multi-GB CUDA build, so lerobot is
   installed ``--no-deps`` beside the packages its data set loader imports (:data:`READER_DEPS`).
2. Exports PushT (3 scripted episodes, with the 96 x 96 camera frames), transfer cube and
   insertion (1 episode each) with ``coursekit.data.lerobot_export``.
3. Runs ``benchmarks/lerobot_reader_probe.py`` in that venv, offline: ``LeRobotDataset(root=...)``,
   a DataLoader over a few batches, and an action chunk through ``delta_timestamps``.
4. Compares everything LeRobot returned with what coursekit exported: lengths, episode lengths,
   fps, task text, every batch value (float32 features, the float64 ``coursekit.*`` columns and
   the images exactly), and the chunk's values and padding at an episode's end. The verdict
   (with the lerobot version) goes to ``benchmarks/results.json``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import venv
from pathlib import Path

import numpy as np

from benchmarks.results import record
from coursekit.data.episodes import EpisodeDataset
from coursekit.data.lerobot_export import export_lerobot, lerobot_frames
from coursekit.data.lerobot_format import INDEX_KEYS

COMMAND = ".venv/bin/python -m benchmarks.check_lerobot_reader"
SECTION = "LeRobot interop"
CACHE = Path.home() / ".cache" / "coursekit" / "lerobot-check"
PROBE = Path(__file__).with_name("lerobot_reader_probe.py")
READER_DEPS = ("torch==2.13.0", "torchvision", "av>=15,<16", "datasets>=4,<5", "huggingface-hub>=0.34.2,<0.36",
               "pandas>=2,<3", "pyarrow", "accelerate", "packaging", "pillow", "numpy", "jsonlines", "draccus==0.10.0",
               "termcolor", "einops")
"""What ``lerobot.datasets.lerobot_dataset`` imports (lerobot itself goes in with --no-deps)."""


def reader_venv(version: str) -> Path:
    """The venv's python, built on first use; raises RuntimeError saying which pip step failed."""
    digest = hashlib.sha256(" ".join(READER_DEPS).encode()).hexdigest()[:8]
    home = CACHE / f"venv-lerobot-{version}-{digest}"
    python = home / "bin" / "python"
    if (home / "ready").is_file():
        return python
    venv.create(home, with_pip=True)  # an interrupted earlier build is completed, not redone
    for step in ([*READER_DEPS], ["--no-deps", f"lerobot=={version}"]):
        res = subprocess.run([str(python), "-m", "pip", "install", "--quiet", *step], capture_output=True, text=True)
        if res.returncode:
            raise RuntimeError(f"pip install {' '.join(step)} failed: {res.stderr.strip()[-2000:]}")
    (home / "ready").write_text("ok\n")
    return python


def demonstrations() -> dict[str, EpisodeDataset]:
    from coursekit.experts.aloha_scripted import collect_insertion, collect_transfer_cube
    from coursekit.experts.pusht_planner import collect_dataset

    return {"pusht": collect_dataset(3, 0, progress=False), "transfer_cube": collect_transfer_cube(1, 0, progress=False),
            "insertion": collect_insertion(1, 0, progress=False)}


def expected_columns(dataset: EpisodeDataset, images: bool) -> dict[str, np.ndarray]:
    """Every column of the export as LeRobot should return it (images (N, 3, H, W) in [0, 1])."""
    frames, _ = lerobot_frames(dataset, images=images)
    cols = {k: (v.transpose(0, 3, 1, 2) / 255.0 if frames.features[k].dtype == "image" else v)
            for k, v in frames.columns.items()}
    lengths = dataset.episode_lengths
    frame = np.concatenate([np.arange(n) for n in lengths])
    cols.update(index=np.arange(dataset.n_steps), episode_index=np.repeat(np.arange(len(lengths)), lengths),
                frame_index=frame, timestamp=(frame / frames.fps).astype(np.float32))
    return cols


def compare(i: int, name: str, dataset: EpisodeDataset, seen: dict[str, np.ndarray], info: dict, images: bool) -> list[str]:
    """Differences between what LeRobot returned for folder ``i`` and the export (empty: none)."""
    problems = []
    want = expected_columns(dataset, images)
    if info["len"] != dataset.n_steps or info["episode_lengths"] != dataset.episode_lengths.tolist():
        problems.append(f"{name}: LeRobot sees {info['len']} frames in episodes {info['episode_lengths']}")
    for key, values in want.items():
        got = seen.get(f"{i}/{key}")
        if got is None:
            problems.append(f"{name}: LeRobot's batches lack {key}")
            continue
        exp = values[: len(got)].reshape(got.shape)
        if not (np.array_equal(got, exp.astype(got.dtype)) or (exp.dtype.kind == "f" and np.allclose(got, exp, atol=1e-7, rtol=0))):
            problems.append(f"{name}: {key} differs (max |diff| {np.abs(got - exp).max():.3g})")
    frames, _ = lerobot_frames(dataset, images=images)
    if info["tasks"] != list(frames.tasks) or info["fps"] != frames.fps:
        problems.append(f"{name}: LeRobot reads tasks {info['tasks']} at {info['fps']} fps")
    cameras = [k for k, f in frames.features.items() if f.dtype == "image"]
    if info["camera_keys"] != cameras or set(info["stats_keys"]) != {*frames.features, *INDEX_KEYS}:
        problems.append(f"{name}: LeRobot sees cameras {info['camera_keys']} and statistics of {info['stats_keys']}")
    ends = np.cumsum(dataset.episode_lengths)
    for row, p in enumerate(seen[f"{i}/chunk_picks"]):
        end = int(ends[np.searchsorted(ends, p, side="right")])
        idx = np.arange(p, p + seen[f"{i}/chunk_action"].shape[1])
        if not np.array_equal(seen[f"{i}/chunk_is_pad"][row], idx >= end):
            problems.append(f"{name}: action_is_pad at frame {p} is {seen[f'{i}/chunk_is_pad'][row].tolist()}")
        if not np.array_equal(seen[f"{i}/chunk_action"][row], want["action"][np.minimum(idx, end - 1)]):
            problems.append(f"{name}: the action chunk at frame {p} differs")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lerobot", default="0.4.4", help="lerobot version from PyPI (default 0.4.4)")
    args = parser.parse_args(argv)
    try:
        python = reader_venv(args.lerobot)
    except RuntimeError as exc:
        print(f"cannot build the lerobot venv: {exc}", file=sys.stderr)
        return 2
    data = demonstrations()
    with tempfile.TemporaryDirectory(dir=CACHE) as tmp:
        roots = []
        for name, dataset in data.items():
            root = Path(tmp) / name
            root.mkdir()
            export_lerobot(dataset, root, images=name == "pusht")
            roots.append(str(root))
        env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1", "HF_HOME": str(Path(tmp) / "hf")}
        res = subprocess.run([str(python), str(PROBE), str(Path(tmp) / "seen.npz"), *roots], capture_output=True,
                             text=True, env=env)
        if res.returncode:
            problems, summary = [f"LeRobot's reader failed: {res.stderr.strip()[-3000:]}"], {"lerobot": args.lerobot}
        else:
            summary = json.loads(res.stdout.strip().splitlines()[-1])
            with np.load(Path(tmp) / "seen.npz") as npz:
                seen = dict(npz)
            problems = [p for i, (name, ds) in enumerate(data.items())
                        for p in compare(i, name, ds, seen, summary["folders"][i], images=name == "pusht")]
    verdict = "pass" if not problems else "fail"
    stubbed = "; torchvision's C++ ops stubbed (CUDA build beside the CPU torch)" if summary.get("torchvision_ops_stubbed") else ""
    note = (f"lerobot {summary.get('lerobot')} from PyPI, installed --no-deps beside torch {summary.get('torch', '?')}{stubbed}; "
            f"LeRobotDataset(root=...) offline on "
            f"PushT (3 episodes, images), transfer cube, insertion: every value of 4 batches of 16 and an action chunk "
            f"with episode-end padding equal to the export" + ("" if not problems else "; " + " | ".join(problems)[:600]))
    print(verdict, note)
    record(SECTION, f"LeRobot's LeRobotDataset reads coursekit export lerobot (lerobot {summary.get('lerobot')})",
           verdict, "", COMMAND, target="pass", note=note)
    return 0 if not problems else 1


if __name__ == "__main__":
    raise SystemExit(main())
