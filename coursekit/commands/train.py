"""``coursekit train``: train a chunk policy on PushT demonstrations and write a checkpoint.

Examples::

    coursekit collect pusht --episodes 200 --out demos.npz
    coursekit train --policy diffusion --data demos.npz --minutes 20 --out runs/dp        # CPU, state
    coursekit train --recipe cpu --data demos.npz --minutes 20 --out runs/dp_cpu          # lr 5e-4, batch 128
    coursekit train --policy regression --data demos.npz --minutes 20 --out runs/reg     # the baseline
    coursekit collect aloha-cube --out cube.npz
    coursekit train --policy act --recipe cpu --data cube.npz --minutes 30 --out runs/act_cube  # ACT
    # images (the paper's image PushT setting) -- a GPU job:
    coursekit train --policy diffusion --features pusht_image --unet paper_image --vision resnet18 \
        --device cuda --data demos.npz --steps 200000 --out runs/dp_image
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

HELP = "train a chunk policy (diffusion, regression baseline or act) on demonstrations and write a checkpoint"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policy", choices=["diffusion", "regression", "act", "flow"], default="diffusion",
                        help="policy head (default: diffusion; act = ACT, the transformer CVAE; flow = flow matching)")
    parser.add_argument("--data", type=Path, required=True, help="demonstrations .npz (from `coursekit collect ...`)")
    parser.add_argument("--out", type=Path, required=True, help="checkpoint directory to write (model.safetensors + config.json)")
    parser.add_argument("--minutes", type=float, default=None, help="wall-clock training budget in minutes")
    parser.add_argument("--steps", type=int, default=None, help="optimiser steps (default: until --minutes is used up)")
    parser.add_argument("--features", choices=["pusht_state", "pusht_keypoints", "pusht_image", "aloha_state", "aloha_qpos"],
                        default=None, help="observation features (default: pusht_state = agent xy, block xy, sin/cos "
                                           "angle for diffusion/regression; read from the data for act)")
    parser.add_argument("--chunk-size", type=int, default=None, help="k, actions per ACT chunk (default: ACTConfig's)")
    parser.add_argument("--unet", default="cpu", help="U-Net size preset: cpu (default), paper_lowdim, paper_image")
    parser.add_argument("--down-dims", default=None, help="override the preset's U-Net channels, e.g. 32,64,128")
    parser.add_argument("--vision", default="cpu", help="image encoder preset for --features pusht_image: cpu (default), resnet18")
    parser.add_argument("--n-action-steps", type=int, default=8, help="Ta, actions executed per chunk (default 8)")
    parser.add_argument("--recipe", choices=["paper", "cpu"], default="paper",
                        help="paper (default): the paper's optimiser (DP lr 1e-4, batch 256; ACT lr 1e-5, batch 8); "
                             "cpu: tuned for a 20-30 minute CPU budget (DP lr 5e-4, batch 128; ACT lr 3e-4, batch 16)")
    parser.add_argument("--batch-size", type=int, default=None, help="batch size (default: the recipe's; 64 for images)")
    parser.add_argument("--lr", type=float, default=None, help="peak learning rate (default: the recipe's)")
    parser.add_argument("--warmup-steps", type=int, default=None, help="linear LR warm-up steps (default: the recipe's)")
    parser.add_argument("--lr-schedule", choices=["cosine", "constant"], default=None,
                        help="after warm-up: cosine decay to 0 over the budget or constant (default: the recipe's; "
                             "cosine, except ACT --recipe paper: constant)")
    parser.add_argument("--seed", type=int, default=0, help="seed of weights, batches and noise (default 0)")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch CPU threads (default: torch's choice; use 1 on a machine shared with other jobs)")
    parser.add_argument("--device", default="auto", help="auto, cpu, cuda, mps (default auto)")
    parser.add_argument("--init-from", type=Path, default=None,
                        help="warm start: begin from this checkpoint's weights (same policy type, config and data "
                             "normalisers) with a fresh optimiser and LR schedule; its training summary is kept as "
                             "training.init_from in the new checkpoint")
    parser.add_argument("--checkpoint-every", type=float, default=5.0, help="minutes between periodic checkpoints (default 5)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def run(args: argparse.Namespace) -> int:
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.nn.unet1d import UNet1DConfig
    from coursekit.policies.factory import make_pusht_policy
    from coursekit.train import TrainConfig

    if args.minutes is None and args.steps is None:
        raise ValueError("give a budget: --minutes M and/or --steps N")
    if args.policy == "act":
        return _run_act(args)
    features = args.features or "pusht_state"
    if features.startswith("aloha"):
        raise ValueError(f"--features {features} is for --policy act; diffusion/regression train on PushT features here")
    overrides = {"lr": args.lr, "batch_size": args.batch_size or (64 if features == "pusht_image" else None),
                 "warmup_steps": args.warmup_steps, "lr_schedule": args.lr_schedule}
    config = TrainConfig.recipe(args.recipe, **{k: v for k, v in overrides.items() if v is not None}, max_steps=args.steps, minutes=args.minutes,
                                seed=args.seed, num_threads=args.threads,
                                checkpoint_every_minutes=args.checkpoint_every, progress=not args.no_progress)
    unet = UNet1DConfig.preset(args.unet)
    if args.down_dims:
        try:
            dims = tuple(int(v) for v in args.down_dims.split(","))
        except ValueError:
            raise ValueError(f"--down-dims must be comma-separated ints like 32,64,128, got {args.down_dims!r}") from None
        unet = dataclasses.replace(unet, down_dims=dims)
    extra = {}
    if features == "pusht_image":
        from coursekit.nn.vision import VisionEncoderConfig

        extra["vision"] = VisionEncoderConfig.preset(args.vision)
    dataset = EpisodeDataset.load(args.data)
    policy, batches = make_pusht_policy(args.policy, dataset, features=features, batch_size=config.batch_size,
                                        seed=args.seed, device=args.device, unet=unet,
                                        n_action_steps=args.n_action_steps, **extra)
    meta = {**dataset.meta, "path": str(args.data), "n_steps": dataset.n_steps, "n_episodes": dataset.n_episodes}
    print(f"{args.policy} policy, {policy.num_parameters() / 1e6:.2f} M parameters, {len(batches)} windows "
          f"from {dataset.n_episodes} episodes; device {policy.device}")
    return _train_and_report(policy, batches, config, args, meta)


def _run_act(args: argparse.Namespace) -> int:
    """ACT: the same trainer and checkpoint format; its optimiser recipe from ``act_train_config``."""
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.policies.act_factory import act_train_config, make_act_policy

    overrides = {"lr": args.lr, "batch_size": args.batch_size, "warmup_steps": args.warmup_steps,
                 "lr_schedule": args.lr_schedule}
    config = act_train_config(args.recipe, **{k: v for k, v in overrides.items() if v is not None},
                              max_steps=args.steps, minutes=args.minutes, seed=args.seed, num_threads=args.threads,
                              checkpoint_every_minutes=args.checkpoint_every, progress=not args.no_progress)
    dataset = EpisodeDataset.load(args.data)
    extra = {} if args.chunk_size is None else {"chunk_size": args.chunk_size}
    policy, batches = make_act_policy(dataset, features=args.features, batch_size=config.batch_size, seed=args.seed,
                                      device=args.device, **extra)
    meta = {**dataset.meta, "path": str(args.data), "n_steps": dataset.n_steps, "n_episodes": dataset.n_episodes}
    print(f"act policy ({policy.config.features}), {policy.num_parameters() / 1e6:.2f} M parameters, "
          f"k = {policy.config.chunk_size}, {dataset.n_episodes} episodes; device {policy.device}")
    return _train_and_report(policy, batches, config, args, meta)


def warm_start(policy, path: Path) -> dict:
    """Copy the weights of the checkpoint ``path`` into ``policy``; returns that checkpoint's provenance.

    The checkpoint must hold the same policy type with the same config and the same normalisers
    (i.e. it was trained on the same kind of data): anything else is refused with the difference.
    Only weights carry over; the optimiser state does not (checkpoints do not store it), so the
    continued run starts a fresh warm-up + schedule.
    """
    from coursekit.checkpoint import CheckpointError, load_checkpoint, read_checkpoint_info
    from coursekit.config import config_to_dict
    from coursekit.policies.base import normalizers_to_json

    source = load_checkpoint(path, device=policy.device, expected_type=policy.policy_type)
    mine, theirs = config_to_dict(policy.config), config_to_dict(source.config)
    diff = {k: (theirs.get(k), mine.get(k)) for k in sorted(set(mine) | set(theirs)) if mine.get(k) != theirs.get(k)}
    if diff:
        raise CheckpointError(f"--init-from {str(path)!r}: its config differs from this run's as (checkpoint, run): {diff}")
    if normalizers_to_json(source.normalizers) != normalizers_to_json(policy.normalizers):
        raise CheckpointError(f"--init-from {str(path)!r}: its normalisers differ from those fitted on {policy.policy_type} "
                              f"training data here; warm-start only on the same demonstrations")
    policy.load_state_dict(source.state_dict())
    info = read_checkpoint_info(path)
    training = info.get("training") or {}
    return {"path": str(path), **{k: training.get(k) for k in ("steps", "seconds", "samples_per_s", "torch_threads", "init_from")}}


def _train_and_report(policy, batches, config, args: argparse.Namespace, meta: dict) -> int:
    from coursekit.train import train

    prior = warm_start(policy, args.init_from) if getattr(args, "init_from", None) is not None else None
    if prior is not None:
        print(f"warm start from {args.init_from} ({prior['steps']} steps, {prior['seconds']} s)")
    result = train(policy, batches, config, out_dir=args.out, dataset_meta=meta, init_from=prior)
    s = result.summary
    print(json.dumps({k: s[k] for k in ("steps", "seconds", "samples_per_s", "final_loss")}))
    print(f"wrote {args.out}")
    return 0
