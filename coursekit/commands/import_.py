"""``coursekit import lerobot DIR OUT.npz``: a LeRobotDataset v3.0 folder as coursekit demonstrations.

A folder ``coursekit export lerobot`` wrote comes back exactly; a LeRobot set (for instance one
downloaded with LeRobot) is mapped by LeRobot's conventions (see ``coursekit.data.lerobot_import``).
The .npz then trains with ``coursekit train --data OUT.npz``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from coursekit.commands._args import output_path

HELP = "read demonstrations from another format (lerobot: a local LeRobotDataset v3.0 folder)"


def _feature_list(text: str) -> list[str]:
    keys = [k.strip() for k in text.split(",")]
    if not all(keys):
        raise argparse.ArgumentTypeError(f"must be comma-separated LeRobot feature keys like "
                                         f"observation.state,observation.environment_state, got {text!r}")
    return keys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from coursekit.data.lerobot_tasks import TASKS

    sub = parser.add_subparsers(dest="format", metavar="FORMAT", required=True)
    p = sub.add_parser("lerobot", help="a local LeRobotDataset v3.0 folder",
                       description="Read a local LeRobotDataset v3.0 folder into a coursekit data set (.npz).")
    p.add_argument("folder", type=Path, metavar="DIR", help="the LeRobot data set's folder (with meta/info.json)")
    p.add_argument("out", type=output_path, metavar="OUT", help="the .npz to write")
    p.add_argument("--features", type=_feature_list, default=None,
                   help="LeRobot observation features to import, comma-separated (default: every one coursekit maps; "
                        "action always); on a coursekit export this maps by LeRobot's conventions instead of restoring")
    p.add_argument("--as", dest="as_task", choices=sorted(TASKS), default=None,
                   help="the coursekit task, when the folder cannot tell it (arm-pair sets without object poses)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing data set at OUT (atomically: the old file stays until the new one is complete)")


def run(args: argparse.Namespace) -> int:
    from coursekit.commands._lerobot_io import claim_import_out
    from coursekit.data.lerobot_import import import_lerobot

    with claim_import_out(args.out, args.folder, args.overwrite) as lock:
        dataset, notes = import_lerobot(args.folder, features=args.features, as_task=args.as_task)
        for note in notes:
            print(f"note: {note}")
        dataset.save(args.out, lock=lock)
    print(f"wrote {args.out}: {dataset.n_episodes} episodes, {dataset.n_steps} steps, arrays "
          f"{', '.join(f'{k}{tuple(v.shape[1:])}' for k, v in dataset.arrays.items())}; "
          f"train with: coursekit train --data {args.out} --out RUN --steps N")
    return 0
