"""``coursekit train``: train any chunk policy on any task's demonstrations and write a run folder.

The run folder (--out) holds the checkpoint (model.safetensors + config.json, rewritten every
--checkpoint-every minutes and at the end), metrics.csv (step, loss, lr, samples/s, wall time)
and loss.png, both written during training. With --resume (a step budget) it also holds
train_state.pt while training: everything the remaining steps depend on, rewritten at least every
minute; if the run is stopped, the same command continues it with the same bytes as a run that was
never stopped, and the file is removed when the run is complete.

Examples::

    coursekit collect pusht --episodes 200 --out demos.npz
    coursekit train --policy diffusion --data demos.npz --minutes 20 --out runs/dp        # CPU, state
    coursekit train --recipe cpu --data demos.npz --minutes 20 --out runs/dp_cpu          # lr 5e-4, batch 128
    coursekit train --policy regression --data demos.npz --minutes 20 --out runs/reg     # the baseline
    coursekit train --recipe cpu --data demos.npz --steps 20000 --resume --out runs/long  # stop it; run it again
    coursekit collect aloha-cube --out cube.npz
    coursekit train --policy act --recipe cpu --data cube.npz --minutes 30 --out runs/act_cube  # ACT
    coursekit train --policy diffusion --recipe cpu --data cube.npz --minutes 30 --out runs/dp_cube  # DP, arm pair
    # images (the paper's image PushT setting) -- a GPU job:
    coursekit train --policy diffusion --features pusht_image --unet paper_image --vision resnet18 \
        --device cuda --data demos.npz --steps 200000 --out runs/dp_image
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

from coursekit.commands._args import device, float_in, int_in, int_list_in, output_path, seed_int, threads

from coursekit.data.features import FEATURES, get_features  # numpy only: `coursekit --help` stays instant
from coursekit.policies import POLICY_TYPES  # the registry itself (no torch until a class is used)

STATE_NAME = "train_state.pt"
"""The resume state inside a run folder trained with --resume (removed when the run is complete)."""
HELP = "train a chunk policy (diffusion, regression baseline or act) on PushT or arm-pair demonstrations"

# Bounds of the numeric flags: beyond them a value cannot be meant (a budget of 1e-300 minutes trains
# no step; 100000 U-Net channels or an ACT chunk of 1e6 actions cannot fit in memory).
MIN_MINUTES, MAX_MINUTES = 0.01, 100_000.0
MAX_STEPS = 1_000_000_000
MAX_CHUNK_SIZE = 1000
MAX_CHANNELS, MAX_LEVELS = 4096, 6


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policy", choices=sorted(POLICY_TYPES), default="diffusion",
                        help="policy head (default: diffusion; act = ACT, the transformer CVAE; flow = flow matching, chapter 10)")
    parser.add_argument("--data", type=Path, required=True, help="demonstrations .npz (from `coursekit collect ...`)")
    parser.add_argument("--out", type=output_path, required=True,
                        help="run folder to create: checkpoint (model.safetensors + config.json), metrics.csv, loss.png")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing run at --out: the new run trains in a hidden folder beside it and "
                             "replaces the old one only when complete")
    parser.add_argument("--minutes", type=float_in(MIN_MINUTES, MAX_MINUTES), default=None,
                        help=f"wall-clock training budget in minutes, {MIN_MINUTES:g} to {MAX_MINUTES:g}")
    parser.add_argument("--steps", type=int_in(1, MAX_STEPS), default=None,
                        help="optimiser steps (default: until --minutes is used up)")
    parser.add_argument("--features", choices=sorted(FEATURES), default=None,
                        help="observation features (default: from the data: pusht_state = agent xy, block xy, sin/cos "
                             "angle for PushT, aloha_state = qpos + object poses for the arm pair)")
    parser.add_argument("--chunk-size", type=int_in(1, MAX_CHUNK_SIZE), default=None,
                        help=f"k, actions per ACT chunk, at most {MAX_CHUNK_SIZE} and the longest episode (default: ACTConfig's)")
    parser.add_argument("--horizon", type=int_in(2, MAX_CHUNK_SIZE), default=None,
                        help="Tp, actions per predicted chunk of diffusion, flow and regression heads (default 16, "
                             "divisible by 2**(U-Net levels - 1)); ACT's is --chunk-size")
    parser.add_argument("--unet", default=None, help="U-Net size preset: cpu (default), paper_lowdim, paper_image")
    parser.add_argument("--down-dims", type=int_list_in(1, MAX_CHANNELS, MAX_LEVELS), default=None,
                        help=f"override the preset's U-Net channels, e.g. 32,64,128 (each at most {MAX_CHANNELS})")
    parser.add_argument("--vision", default=None, help="image encoder preset for image features (pusht_image, aloha_image): cpu (default), resnet18, arm_pair, small "
                             "(96x96 frames encoded at 48x48: the CPU route of chapter 12)")
    parser.add_argument("--n-action-steps", type=int_in(1, MAX_CHUNK_SIZE), default=None,
                        help="Ta, actions executed per chunk (default: the policy's, 8 for diffusion/regression)")
    parser.add_argument("--recipe", choices=["paper", "cpu"], default="paper",
                        help="paper (default): the paper's optimiser (DP lr 1e-4, batch 256; ACT lr 1e-5, batch 8); "
                             "cpu: tuned for a 20-30 minute CPU budget (DP lr 5e-4, batch 128; ACT lr 3e-4, batch 16)")
    parser.add_argument("--batch-size", type=int_in(1), default=None,
                        help="batch size, at most the training samples in --data (default: the recipe's; 64 for images)")
    parser.add_argument("--lr", type=float_in(0.0, 1.0, lo_open=True), default=None, help="peak learning rate (default: the recipe's)")
    parser.add_argument("--warmup-steps", type=int_in(0, MAX_STEPS), default=None,
                        help="linear LR warm-up steps, at most --steps (default: the recipe's)")
    parser.add_argument("--lr-schedule", choices=["cosine", "constant"], default=None,
                        help="after warm-up: cosine decay to 0 over the budget or constant (default: the recipe's; "
                             "cosine, except ACT --recipe paper: constant)")
    parser.add_argument("--seed", type=seed_int, default=0, help="seed of weights, batches and noise (default 0)")
    parser.add_argument("--threads", type=threads, default=None,
                        help="torch CPU threads (default: torch's choice; use 1 on a machine shared with other jobs)")
    parser.add_argument("--device", type=device, default="auto", help="auto, cpu, cuda, mps (default auto)")
    parser.add_argument("--init-from", type=Path, default=None,
                        help="warm start: begin from this checkpoint's weights (same policy type, config and data "
                             "normalisers) with a fresh optimiser and LR schedule; its training summary is kept as "
                             "training.init_from in the new checkpoint")
    parser.add_argument("--checkpoint-every", type=float_in(0.0, MAX_MINUTES, lo_open=True), default=5.0,
                        help="minutes between periodic checkpoints (default 5)")
    parser.add_argument("--resume", action="store_true",
                        help=f"keep a resume state ({STATE_NAME}) in --out while training and, when --out holds one "
                             f"from a stopped run, continue that run exactly (needs --steps, not --minutes)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _config_fields(args: argparse.Namespace) -> dict[str, Any]:
    """Policy config fields set on the command line (each refused by a policy type that lacks it)."""
    fields: dict[str, Any] = {}
    if args.unet is not None or args.down_dims:
        from coursekit.nn.unet1d import UNet1DConfig

        unet = UNet1DConfig.preset(args.unet or "cpu")
        if args.down_dims:
            unet = dataclasses.replace(unet, down_dims=args.down_dims)
        fields["unet"] = unet
    if args.vision is not None:
        from coursekit.nn.vision import VisionEncoderConfig

        fields["vision"] = VisionEncoderConfig.preset(args.vision)
    if args.chunk_size is not None:
        fields["chunk_size"] = args.chunk_size
    if args.horizon is not None:
        fields["horizon"] = args.horizon
    if args.n_action_steps is not None:
        fields["n_action_steps"] = args.n_action_steps
    return fields


def run(args: argparse.Namespace) -> int:
    """One flow for every policy type and task: claim the output, build, train with callbacks, report."""
    if args.minutes is None and args.steps is None:
        raise ValueError("give a budget: --minutes M and/or --steps N")
    _check_budget(args)
    _check_resume(args)
    with claim_run_out(args) as lock:  # before any work: nothing is loaded, built or written yet
        for leftover in lock.swept:
            print(f"removed {str(leftover)!r}, left by an interrupted earlier run", file=sys.stderr)
        return _train(args, lock)


def _train(args: argparse.Namespace, lock: Any) -> int:
    """Build the policy and its data, train into --out (or a staging folder that replaces it), report."""
    from coursekit.checkpoint import CheckpointSaver, warm_start
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.data.features import default_features
    from coursekit.device import resolve_device
    from coursekit.outputs import replace_dir, staging_dir
    from coursekit.policies import get_policy_class
    from coursekit.policies.factory import make_policy
    from coursekit.train import TrainConfig, train
    from coursekit.train_state import TrainState
    from coursekit.training_log import MetricsLog

    fields = _config_fields(args)
    _check_flags_apply(args, {f.name for f in dataclasses.fields(get_policy_class(args.policy).config_class)}, fields)
    resolve_device(args.device)  # an unavailable device is refused before the data is read
    dataset = EpisodeDataset.load(args.data)
    features = args.features or default_features(dataset.arrays, dataset.meta)
    check_against_data(args, dataset, features)
    if args.vision is not None and get_features(features).obs_type != "image":
        raise ValueError(f"--vision {args.vision} applies to image features (--features pusht_image or aloha_image), "
                         f"not {features}")
    overrides = {"lr": args.lr, "batch_size": args.batch_size or (64 if features == "pusht_image" else None),
                 "warmup_steps": args.warmup_steps, "lr_schedule": args.lr_schedule}
    overrides = {k: v for k, v in overrides.items() if v is not None}
    policy, batches, recipe = make_policy(args.policy, dataset, features=features, recipe=args.recipe,
                                          batch_size=overrides.get("batch_size"), seed=args.seed, device=args.device,
                                          **fields)
    _check_batch_size(args, len(batches))
    config = TrainConfig(**{**recipe, **overrides}, max_steps=args.steps, minutes=args.minutes, seed=args.seed,
                         num_threads=args.threads, checkpoint_every_minutes=args.checkpoint_every,
                         progress=not args.no_progress)
    cut = f" (batch size {config.batch_size} cut to them)" if config.batch_size > len(batches) else ""
    meta = {**dataset.meta, "path": str(args.data), "n_steps": dataset.n_steps, "n_episodes": dataset.n_episodes}
    print(f"{args.policy} policy on {features}, {policy.num_parameters() / 1e6:.2f} M parameters, {len(batches)} "
          f"training samples from {dataset.n_episodes} episodes{cut}; device {policy.device}")
    prior = warm_start(policy, args.init_from) if args.init_from is not None else None
    if prior is not None:
        print(f"warm start from {args.init_from} ({prior['steps']} steps, {prior['seconds']} s)")
    resume_at = TrainState.saved_step(args.out / STATE_NAME) if _resuming(args) else None
    if resume_at is not None:
        print(f"resuming {args.out} at step {resume_at} of {args.steps}")
    with contextlib.ExitStack() as stack:
        run_dir = args.out
        if args.out.exists() and any(args.out.iterdir()) and resume_at is None:  # --overwrite: keep the old run
            run_dir = stack.enter_context(staging_dir(args.out, lock))  # until the new one is complete
            print(f"training in {run_dir}; it replaces {args.out} when complete")
        saver = CheckpointSaver(run_dir, dataset_meta=meta, lock=lock)
        state = run_dir / STATE_NAME if args.resume else None
        with MetricsLog(run_dir, lock=lock, resume_at=resume_at) as metrics:  # metrics.csv + loss.png, during training
            result = train(policy, batches, config, callbacks=[saver, metrics], init_from=prior, state_file=state)
        if state is not None:
            state.unlink(missing_ok=True)  # complete: nothing left to resume
        if run_dir != args.out:
            replace_dir(run_dir, args.out, lock)  # one atomic exchange; the old run is then removed with the staging folder
    s = result.summary
    print(json.dumps({k: s[k] for k in ("steps", "seconds", "samples_per_s", "final_loss")}))
    print(f"wrote {args.out}")
    return 0


def run_dir_foreign(path: Path) -> str | None:
    """None if ``path`` is a run folder `coursekit train` wrote, else which of its files is not a run's.

    A run folder holds nothing but a run's files (checkpoint, metrics.csv, loss.png), each a
    regular file, and either a readable checkpoint or a metrics.csv with the trainer's own header:
    a user's folder never qualifies.
    """
    from coursekit.checkpoint import CONFIG_FILE, WEIGHTS_FILE, is_checkpoint_dir
    from coursekit.outputs import regular_file
    from coursekit.training_log import COLUMNS, LOSS_PLOT_NAME, METRICS_NAME

    names = sorted(p.name for p in path.iterdir())
    for name in names:
        if name not in (CONFIG_FILE, WEIGHTS_FILE, METRICS_NAME, LOSS_PLOT_NAME, STATE_NAME):
            return f"it holds {name!r}, which a run never writes"
        if not regular_file(path / name):
            return f"its {name!r} is not a regular file"
    if is_checkpoint_dir(path):
        return None
    if CONFIG_FILE in names or WEIGHTS_FILE in names:
        return f"its {CONFIG_FILE if CONFIG_FILE in names else WEIGHTS_FILE!r} is not a coursekit checkpoint's"
    try:
        with open(path / METRICS_NAME, encoding="utf-8") as fh:
            if fh.readline().strip() == ",".join(COLUMNS):
                return None
    except (OSError, UnicodeDecodeError):
        pass
    return f"it has no checkpoint, and no {METRICS_NAME!r} with the trainer's header"


def claim_run_out(args: argparse.Namespace) -> contextlib.AbstractContextManager:
    """Check --out (new, empty, or with --overwrite an earlier run; never the data or inside it) and lock it."""
    from coursekit.outputs import claim_output

    return claim_output(args.out, what="coursekit run folder", foreign=run_dir_foreign, directory=True,
                        overwrite=args.overwrite or _resuming(args), inputs=[args.data, args.init_from])


def _resuming(args: argparse.Namespace) -> bool:
    """--resume and --out holds the resume state of a stopped run."""
    return bool(getattr(args, "resume", False)) and (args.out / STATE_NAME).is_file()


def _check_resume(args: argparse.Namespace) -> None:
    """Refuse --resume where no exact continuation is defined, before any work."""
    if not getattr(args, "resume", False):
        return
    if args.minutes is not None or args.steps is None:
        raise ValueError(f"--resume needs a step budget (--steps N) and no --minutes (got --minutes {args.minutes}): "
                         f"with a time budget the steps trained depend on the machine's speed")
    if args.overwrite:
        raise ValueError("--resume continues the run at --out; --overwrite replaces it: give one of them")
    if args.out.is_dir() and any(args.out.iterdir()) and not (args.out / STATE_NAME).is_file():
        raise ValueError(f"--resume: {str(args.out)!r} holds no resume state ({STATE_NAME}): it is a finished run "
                         f"or not a run; give a new --out, or --overwrite to train it again")


def _check_flags_apply(args: argparse.Namespace, config_fields: set[str], fields: dict[str, Any]) -> None:
    """Refuse a flag the chosen policy has no use for, naming the flag, its value and the policy."""
    flag_of = {"unet": "unet" if args.down_dims is None else "down-dims", "vision": "vision", "chunk_size": "chunk-size",
               "n_action_steps": "n-action-steps"}
    for name in sorted(set(fields) - config_fields):
        flag = flag_of.get(name, name.replace("_", "-"))
        value = getattr(args, flag.replace("-", "_"), None)
        shown = ",".join(map(str, value)) if isinstance(value, tuple) else value
        raise ValueError(f"--{flag} {shown} does not apply to --policy {args.policy}")
    if args.n_action_steps is not None and "temporal_ensembling" in config_fields:
        raise ValueError(f"--n-action-steps {args.n_action_steps} does not apply to --policy {args.policy}: it executes "
                         f"by temporal ensembling (choose Ta when evaluating: coursekit eval CKPT --no-ensembling "
                         f"--n-action-steps N)")


def _check_budget(args: argparse.Namespace) -> None:
    """Refuse an explicit warm-up longer than the step budget: the LR would never reach its peak."""
    if args.warmup_steps is not None and args.steps is not None and args.warmup_steps > args.steps:
        raise ValueError(f"--warmup-steps {args.warmup_steps} is more than --steps {args.steps}: the learning rate "
                         f"would never reach its peak; give at most {args.steps}")


def check_against_data(args: argparse.Namespace, dataset: Any, features: str) -> None:
    """Before building anything: the demonstrations fit the task, and --chunk-size fits their episodes."""
    from coursekit.data.validate import check_training_data

    check_training_data(dataset, features, source=f"--data {str(args.data)!r}")
    longest = int(dataset.episode_lengths.max())
    if args.chunk_size is not None and args.chunk_size > longest:
        raise ValueError(f"--chunk-size {args.chunk_size} is longer than the longest episode in {str(args.data)!r} "
                         f"({longest} steps): every chunk would be mostly padding; give at most {longest}")


def _check_batch_size(args: argparse.Namespace, n_samples: int) -> None:
    """Refuse a --batch-size the data cannot fill (it would be cut to the samples there are, silently)."""
    if args.batch_size is not None and args.batch_size > n_samples:
        raise ValueError(f"--batch-size {args.batch_size} is more than the {n_samples} training samples in "
                         f"{str(args.data)!r}; give at most {n_samples}")

