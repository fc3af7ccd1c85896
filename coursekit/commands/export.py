"""``coursekit export lerobot DATA.npz OUT_DIR``: demonstrations as a LeRobotDataset v3.0 folder.

The folder is what LeRobot's ``LeRobotDataset(repo_id, root=OUT_DIR)`` loads and its trainer
takes (features named as LeRobot's own PushT and ALOHA sets name them; see
``coursekit.data.lerobot_export``), and ``coursekit import lerobot`` turns back into the same .npz.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from coursekit.commands._args import output_path, positive_int

HELP = "write demonstrations in another format (lerobot: a LeRobotDataset v3.0 folder)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="format", metavar="FORMAT", required=True)
    p = sub.add_parser("lerobot", help="a LeRobotDataset v3.0 folder (parquet frames + meta/)",
                       description="Write coursekit demonstrations as a LeRobotDataset v3.0 folder.")
    p.add_argument("data", type=Path, help="demonstrations .npz (from `coursekit collect ...` or `coursekit import ...`)")
    p.add_argument("out", type=output_path, metavar="OUT_DIR",
                   help="folder to write: new or empty (or an earlier export, with --overwrite)")
    p.add_argument("--fps", type=positive_int, default=None,
                   help="frames per second; must be the task's control rate (10 PushT, 50 arm pair), the default")
    p.add_argument("--task", default=None, help="the task's text in meta/tasks.parquet (default: one sentence per task)")
    p.add_argument("--images", action="store_true",
                   help="pusht: also write the 96 x 96 camera frames (rendered from the states) as observation.image")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an earlier export at OUT_DIR (atomically: the old one stays until the new one is complete)")


def run(args: argparse.Namespace) -> int:
    from coursekit.commands._lerobot_io import claim_export_out, write_export_folder
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.data.lerobot_export import export_lerobot

    if args.task is not None and not args.task.strip():
        raise ValueError("--task must be a non-empty sentence describing the task, got an empty one")
    with claim_export_out(args.out, args.data, args.overwrite) as lock:
        dataset = EpisodeDataset.load(args.data)
        info = write_export_folder(args.out, lock, lambda folder: export_lerobot(
            dataset, folder, fps=args.fps, task_text=args.task, images=args.images))
    shown = [k for k in info["features"] if not k.startswith("coursekit.")]
    print(f"wrote {args.out}: LeRobotDataset {info['codebase_version']}, {info['total_episodes']} episodes, "
          f"{info['total_frames']} frames at {info['fps']} fps; features {', '.join(shown)}")
    return 0
