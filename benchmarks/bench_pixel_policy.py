"""From pixels on a CPU (chapter 12): the two-stage route, measured part by part.

Diffusion Policy's image recipe trains a ResNet-18 end to end from the denoising loss: on this
CPU that is hours per thousand steps (``bench_pixels``). The two-stage route spends the budget
differently: (1) pre-train a small encoder to read the block's keypoints from a frame (the
simulator gives them for free: ``coursekit.nn.vision_pretrain``), (2) train Diffusion Policy on
the frozen encoder's features, (3) optionally fine-tune end to end. Parts (``--only``):

- ``pretrain``: stage 1 on the frames of the shipped models' 400 demonstrations (rendered from the
  stored states at 96x96 by the env's own renderer; no caching: ~15 s), episodes 0-359 for
  training and 360-399 held out. Rows: the held-out keypoint error in world pixels (the PushT
  world is 512 px wide; the block's keypoints are 8 polygon corners), the training throughput,
  and the steps and seconds. The encoder is saved under ``--out`` for stage 2.
- ``policy``: Diffusion Policy on ``pusht_image`` features (To = 2 frames of 96x96 + the pusher's
  position; no block pose), recipe cpu, ``--policy-steps`` optimiser steps (resumable), with the
  encoder of ``--route``: ``two-stage`` (stage 1's encoder, frozen) or ``end-to-end`` (trained from
  scratch by the denoising loss, as in the paper); then scored on the 200 protocol seeds through
  the same evaluation as ``coursekit eval``. Rows: the score with its interval, and the training
  samples/s and seconds (equal CPU budgets compare routes by seconds, not steps).

    .venv/bin/python -m benchmarks.bench_pixel_policy --only pretrain --pretrain-steps 3000 --threads 1
    .venv/bin/python -m benchmarks.bench_pixel_policy --only pretrain --pretrain-steps 5 --episodes-limit 12 --no-record  # smoke
    .venv/bin/python -m benchmarks.bench_pixel_policy --only policy --route two-stage --policy-steps 19259 --threads 1

The encoder (:data:`ENCODER`) takes 96x96 frames and works at 48x48 (area resize), random 42x42
crops in training: a departure from the paper's 84x84 crops of full-size frames, chosen from the
throughput rows of ``bench_pixels``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from benchmarks.bench_chunk_ablation import DATA
from benchmarks.resumable import cache_dir

SECTION = "Pixels (PushT): two-stage route"
COMMAND = ".venv/bin/python -m benchmarks.bench_pixel_policy"
CACHE = cache_dir("pixels")
SHIPPED = Path(__file__).resolve().parents[1] / "coursekit" / "checkpoints" / "pusht_diffusion_pixels"
"""Where ``--ship`` puts the two-stage pixel policy (never over an existing one)."""
HELD_OUT = 40
"""The last episodes of the data set, never trained on by stage 1 (its keypoint error is measured there)."""


def encoder_config(random_crops: bool = True):
    """The ``small`` preset; ``random_crops=False``: the same encoder without its augmentation."""
    import dataclasses

    from coursekit.nn.vision import VisionEncoderConfig

    return dataclasses.replace(VisionEncoderConfig.preset("small"), random_crops=random_crops)


def variant(args: argparse.Namespace) -> tuple[str, str, str]:
    """(file-name suffix, row-name suffix, command flag) of ``--no-random-crops``; empty without it."""
    if args.random_crops:
        return "", "", ""
    return "_nocrops", " without random crops", " --no-random-crops"


def stage1_path(args: argparse.Namespace) -> Path:
    """Stage 1's encoder file under ``--out``: named by every argument that changes it."""
    return args.out / (f"encoder_pretrained_s{args.pretrain_steps}_b{args.batch_size}_seed{args.seed}"
                       f"{variant(args)[0]}.pt")


def frames_and_keypoints(data: Path, limit: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3, 96, 96) uint8 frames, (N, 16) block keypoints in world px, (N,) episode index."""
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.data.features import pusht_keypoint_features, training_arrays

    ds = EpisodeDataset.load(data)
    ends = np.asarray(ds.episode_ends)
    if limit is not None:  # the first ``limit`` episodes (smoke runs)
        ends = ends[:limit]
        ds = EpisodeDataset({k: v[:ends[-1]] for k, v in ds.arrays.items()}, ends, ds.meta)
    arrays, _ = training_arrays(ds, "pusht_image", image_size=(96, 96))
    keypoints = pusht_keypoint_features(np.asarray(ds["state"]))[:, 2:]  # (N, 2K): the block's, not the agent's
    episode = np.searchsorted(ends, np.arange(len(keypoints)), side="right")  # (N,)
    return arrays["image"], keypoints.astype(np.float32), episode


def stage1(args: argparse.Namespace, frames: np.ndarray, keypoints: np.ndarray, path: Path):
    """Stage 1 trained on ``frames`` -> ``keypoints`` and saved at ``path``, or loaded from it when a
    run with these arguments finished before: (encoder, {"readout", "mean", "std"}, training seconds)."""
    import torch
    from torch import nn

    from coursekit.atomic import atomic_path
    from coursekit.config import config_to_dict
    from coursekit.nn.vision import VisionEncoder
    from coursekit.nn.vision_pretrain import PretrainConfig, pretrain_encoder

    torch.manual_seed(args.seed)
    encoder = VisionEncoder(encoder_config(args.random_crops))
    if path.is_file():  # finished before (e.g. by a --no-record run): measure it again, do not retrain
        saved = torch.load(path, weights_only=False)
        encoder.load_state_dict(saved["encoder"])
        readout = nn.Linear(encoder.config.feature_dim, keypoints.shape[1])
        readout.load_state_dict(saved["readout"])
        print(f"stage 1: loaded {path}")
        return encoder, {"readout": readout, "mean": saved["mean"], "std": saved["std"], "load": saved.get("load")}, \
            saved["seconds"]
    config = PretrainConfig(steps=args.pretrain_steps, batch_size=args.batch_size, seed=args.seed)
    t0 = time.perf_counter()
    out = pretrain_encoder(encoder, frames, keypoints, config)
    seconds = time.perf_counter() - t0
    out["load"] = os.getloadavg()[0]  # how busy the machine was as it trained: the throughput depends on it
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:  # the cache stage 2 loads; a killed write leaves no half file
        torch.save({"encoder": encoder.state_dict(), "config": json.dumps(config_to_dict(encoder.config)),
                    "readout": out["readout"].state_dict(), "mean": out["mean"], "std": out["std"],
                    "seconds": seconds, "load": out["load"]}, tmp)
    return encoder, out, seconds


def part_pretrain(args: argparse.Namespace, record) -> None:
    import torch

    from coursekit.nn.vision_pretrain import predict_targets
    from coursekit.stats import mean_estimate

    t0 = time.perf_counter()
    frames, keypoints, episode = frames_and_keypoints(args.data, args.episodes_limit)
    render_s = time.perf_counter() - t0
    held = episode >= episode.max() + 1 - HELD_OUT if args.episodes_limit is None else episode >= episode.max()
    encoder, out, train_s = stage1(args, frames[~held], keypoints[~held], stage1_path(args))
    pred = predict_targets(encoder, out["readout"], out["mean"], out["std"], frames[held])  # (n, 2K)
    err = np.linalg.norm((pred - keypoints[held]).reshape(len(pred), -1, 2), axis=-1)  # (n, K) world px
    per_frame = err.mean(1)  # (n,)
    est = mean_estimate(per_frame)
    images_s = args.pretrain_steps * args.batch_size / train_s
    print(f"stage 1: {len(frames)} frames rendered in {render_s:.0f} s; {args.pretrain_steps} steps in {train_s:.0f} s "
          f"({images_s:.0f} images/s); held-out keypoint error {est.value:.1f} px [{est.lo:.1f}, {est.hi:.1f}] "
          f"(median {np.median(per_frame):.1f}, n={est.n} frames of {len(np.unique(episode[held]))} episodes)")
    cmd = (f"{COMMAND} --only pretrain --pretrain-steps {args.pretrain_steps} --batch-size {args.batch_size} --threads "
           f"{args.threads}{variant(args)[2]}")
    note = (f"8 block keypoints (world px, 512 px wide world), mean distance per frame over the frames of the last "
            f"{len(np.unique(episode[held]))} of {episode.max() + 1} demonstrations (never trained on); encoder 16-128 "
            f"one block per stage, 96x96 frames at 48x48, 42x42 "
            f"{'random' if args.random_crops else 'centre (no augmentation)'} crops; {args.pretrain_steps} steps of "
            f"batch {args.batch_size}, seed {args.seed}; "
            + (f"1-min load {out['load']:.1f} at the end of training" if out.get("load") is not None
               else "load during training not recorded"))
    record(SECTION, f"stage 1{variant(args)[1]}: held-out block keypoint error", round(est.value, 2), "px", cmd,
           interval=(round(est.lo, 2), round(est.hi, 2)), n=est.n, note=note)
    record(SECTION, f"stage 1{variant(args)[1]}: training throughput", round(images_s), "images/s", cmd,
           note=f"{train_s:.0f} s for {args.pretrain_steps} steps on {torch.get_num_threads()} thread(s); {note}")
    record(SECTION, "rendering the demonstrations' frames (once, before training)", round(len(frames) / render_s),
           "frames/s", cmd, note=f"{len(frames)} frames of 96x96 in {render_s:.0f} s: the env's own renderer on the "
           f"stored states, single process; the data sets keep states, a policy's trainer renders them once")


def score_row(route: str, crops_suffix: str = "") -> str:
    """The name of a pixel route's score row ("DP from pixels, two-stage: score"; chapter 12's figure reads it)."""
    return f"DP from pixels, {route}{crops_suffix}: score"


def _pixel_policy(args: argparse.Namespace, dataset):
    """A fresh image DP with the route's encoder: (policy, batches, recipe)."""
    import torch

    from coursekit.nn.vision_pretrain import freeze
    from coursekit.policies import make_policy

    policy, batches, recipe = make_policy("diffusion", dataset, features="pusht_image", recipe="cpu", seed=args.seed,
                                          vision=encoder_config(args.random_crops))
    if args.route == "two-stage":
        path = stage1_path(args)
        if not path.is_file():
            raise SystemExit(f"no stage-1 encoder {path}: run --only pretrain --pretrain-steps {args.pretrain_steps} first")
        policy.vision_encoder.load_state_dict(torch.load(path, weights_only=False)["encoder"])
        freeze(policy.vision_encoder)  # stage 2: only the U-Net (and the condition's projections) learn
    return policy, batches, recipe


def part_policy(args: argparse.Namespace, record) -> None:
    from benchmarks.bench_chunk_ablation import evaluate_saved
    from benchmarks.resumable import load_or_train
    from coursekit.checkpoint import read_checkpoint_info
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.stats import mean_estimate

    run = args.out / (f"dp_{args.route}_p{args.pretrain_steps if args.route == 'two-stage' else 0}_s{args.policy_steps}"
                      f"_seed{args.seed}{variant(args)[0]}")
    dataset = EpisodeDataset.load(args.data)
    policy = load_or_train(run, lambda: _pixel_policy(args, dataset), args.policy_steps, args.seed, args.threads,
                           dataset.meta)
    training = read_checkpoint_info(run)["training"]
    seeds = list(range(100_000, 100_000 + args.episodes))
    saved = evaluate_saved(lambda: policy, run / f"eval_{seeds[0]}_{len(seeds)}.json", seeds, dataset.meta, {})
    est = mean_estimate(saved["max_reward"])
    label = f"DP from pixels, {args.route}{variant(args)[1]}"
    print(f"{label}: {est.value:.3f} [{est.lo:.3f}, {est.hi:.3f}] (n={est.n}); trained {training['steps']} steps in "
          f"{training['seconds'] / 60:.0f} min ({training['samples_per_s']:.0f} samples/s)")
    cmd = (f"{COMMAND} --only policy --route {args.route} --policy-steps {args.policy_steps} --pretrain-steps "
           f"{args.pretrain_steps} --threads {args.threads} --seed {args.seed}{variant(args)[2]}")
    note = (f"To = 2 frames of 96x96 + pusher position, DDIM-10, Ta = 8; {training['steps']} steps of batch "
            f"{training['train_config']['batch_size']} in {training['seconds'] / 60:.0f} min on {args.threads} thread(s)"
            f"{' after stage 1 (' + str(args.pretrain_steps) + ' steps, encoder frozen)' if args.route == 'two-stage' else ''}; "
            f"training seed {args.seed}; success {np.mean(saved['success']):.3f}")
    record(SECTION, score_row(args.route, variant(args)[1]), round(est.value, 3), "", cmd, interval=(round(est.lo, 3), round(est.hi, 3)),
           n=est.n, seeds=f"{seeds[0]}-{seeds[-1]}", note=note)
    record(SECTION, f"{label}: training throughput", round(training["samples_per_s"]), "samples/s", cmd, note=note)
    if args.ship:
        ship(run, seeds, dataset.meta, f"{cmd} --ship", note, record)


def ship(run: Path, seeds: list[int], meta: dict, cmd: str, note: str, record) -> None:
    """Copy ``run`` into the package as :data:`SHIPPED` (float16 weights, as every shipped checkpoint),
    then score exactly what ships on ``seeds`` through the evaluation ``coursekit eval`` uses."""
    from benchmarks.bench_chunk_ablation import evaluate_saved
    from coursekit.checkpoint import copy_checkpoint_half, load_checkpoint
    from coursekit.stats import mean_estimate

    copy_checkpoint_half(run, SHIPPED)
    saved = evaluate_saved(lambda: load_checkpoint(SHIPPED, device="cpu"), run / f"eval_shipped_{seeds[0]}_{len(seeds)}.json",
                           seeds, meta, {})
    est = mean_estimate(saved["max_reward"])
    print(f"shipped {SHIPPED.name} (float16): {est.value:.3f} [{est.lo:.3f}, {est.hi:.3f}] (n={est.n})")
    record(SECTION, "shipped pixel checkpoint score, DDIM-10 (notebook 12)", round(est.value, 3), "", cmd,
           interval=(round(est.lo, 3), round(est.hi, 3)), n=est.n, seeds=f"{seeds[0]}-{seeds[-1]}",
           note=f"coursekit/checkpoints/{SHIPPED.name}, float16 weights; success {np.mean(saved['success']):.3f}; {note}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="+", choices=["pretrain", "policy"], default=["pretrain"],
                        help="parts to run")
    parser.add_argument("--route", choices=["two-stage", "end-to-end"], default="two-stage", help="policy: its encoder")
    parser.add_argument("--policy-steps", type=int, default=19259, help="policy: optimiser steps (the keypoint DP's)")
    parser.add_argument("--episodes", type=int, default=200, help="policy: protocol seeds to score (protocol: 200)")
    parser.add_argument("--data", type=Path, default=DATA, help=f"demonstrations (default {DATA})")
    parser.add_argument("--pretrain-steps", type=int, default=3000, help="stage-1 optimiser steps")
    parser.add_argument("--batch-size", type=int, default=128, help="frames per stage-1 step")
    parser.add_argument("--seed", type=int, default=0, help="seed of the encoder, batches and crops")
    parser.add_argument("--episodes-limit", type=int, default=None, help="use the first N episodes (smoke runs)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--out", type=Path, default=CACHE, help="trained encoders (never the repository)")
    parser.add_argument("--no-random-crops", dest="random_crops", action="store_false",
                        help="train the encoder on the centre crop (no augmentation): what the crops buy")
    parser.add_argument("--ship", action="store_true",
                        help=f"policy: copy the trained policy to {SHIPPED.relative_to(SHIPPED.parents[2])} (float16) "
                             "and score what ships")
    parser.add_argument("--no-record", action="store_true", help="print only")
    args = parser.parse_args(argv)
    if args.ship and (SHIPPED.exists() or "policy" not in args.only):
        raise SystemExit(f"--ship needs --only policy and no {SHIPPED} (it is never overwritten: move it aside first)"
                         if SHIPPED.exists() else "--ship needs --only policy")
    if not args.data.is_file():
        raise SystemExit(f"--data {args.data} does not exist (make it with: coursekit collect pusht --episodes 400 "
                         f"--seed 0 --action-noise 0,5 --out {args.data})")
    if min(args.pretrain_steps, args.batch_size, args.threads, args.policy_steps, args.episodes) < 1 \
            or (args.episodes_limit or 2) < 2:
        raise SystemExit("--pretrain-steps, --batch-size, --threads, --policy-steps, --episodes must be >= 1 and "
                         "--episodes-limit >= 2")
    import torch

    from benchmarks.results import record as write

    torch.set_num_threads(args.threads)
    record = (lambda *a, **k: None) if args.no_record else write
    if "pretrain" in args.only:
        part_pretrain(args, record)
    if "policy" in args.only:
        part_policy(args, record)


if __name__ == "__main__":
    main()
