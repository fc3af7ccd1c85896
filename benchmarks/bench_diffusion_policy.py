"""Diffusion Policy on PushT: training throughput, a fixed-budget training run, and the shipped checkpoints' scores.

Run on a QUIET machine (the numbers are wall-clock): ``.venv/bin/python -m benchmarks.bench_diffusion_policy``
(about 48 minutes: two 20-minute trainings, evaluations, 2 minutes of throughput). Parts:

- ``throughput``: samples/s of the CPU-default DiffusionPolicy training step (batch 256 and the
  recipe's batch; the trainer as used by ``coursekit train``: batching, loss, AdamW, EMA).
- ``score``: demonstrations from the PushT expert (``--demos`` 400 episodes, seeds 0..),
  alternating clean episodes and DART episodes (``--action-noise 0,5``: the env executes the
  expert's target plus 5 px Gaussian noise, the data keeps the clean target), keypoint features
  (``--features pusht_keypoints``, the paper's low-dim input); DiffusionPolicy trained for
  ``--minutes`` (default 20) on ``--threads`` (default 2) torch threads, evaluated
  with DDIM-10 and DDPM-100 on ``--episodes`` held-out seeds from 100000, 300 steps, mean of max
  reward; the regression baseline (same backbone, data and trainer; ``--regression-minutes``)
  evaluated the same way. ``--policies diffusion`` skips the baseline; ``--reuse`` only re-evaluates.
  This part PRINTS its scores and records none: one training seed under a minutes budget on a
  shared machine is not the protocol (the step-budget curve over 3 training seeds is
  ``bench_chunk_ablation``); it remains the way to train (and ``--ship``) the PushT checkpoints.
  The data and features were chosen on 100 validation seeds (200000..200099), 20 min on one
  thread each: clean 200 demos + (x, y, sin, cos) state 0.78 (2 threads), clean + keypoints 0.73,
  DART 0/10 + state 0.66, DART 0/10 + keypoints 0.80, DART 0/5 + keypoints 0.82.
  ``--ship`` writes the trained checkpoints (float16 weights, about 9 MB each) to
  ``coursekit/checkpoints/pusht_{diffusion,regression}_state`` and evaluates those copies, so the
  recorded scores are exactly what notebook 05 reproduces.
  ``--parallel`` trains both at once with one thread each (about 25 minutes in all, but each
  policy then gets one core, not two). ``--regression-steps match`` trains the baseline for
  exactly as many optimiser steps as the diffusion checkpoint in ``--out`` (the fair comparison
  when the two ran on different thread counts); with ``--reuse`` the DP run is only re-scored.
- ``shipped``: scores ``coursekit/checkpoints/pusht_{diffusion,regression}_state`` with notebook
  05's sampler (DDIM-10 for DP) on ``--episodes`` (default 200) protocol seeds from 100000, with
  bootstrap intervals (DDPM-100 on the same seeds: ``bench_claims``); ``tests/test_shipped_checkpoints.py`` re-checks
  the checkpoints episode by episode through ``coursekit eval`` (``benchmarks/shipped_golden.py``).
- Recipe: ``--recipe cpu`` (default: lr 5e-4, batch 128, a deliberate departure for a 20-minute
  budget, see ``TrainConfig.recipe``) or ``--recipe paper`` (lr 1e-4, batch 256). Other variants:
  ``--down-dims 48,96,192``, ``--batch-size``, ``--lr``.

With ``--threads 2`` on a machine shared with other jobs, torch's two OpenMP threads wait for
each other at every op and training slows down by one to two orders of magnitude: measure on an
otherwise idle machine (the load average at the start is recorded in each note).

Every recorded figure goes through ``benchmarks.results.record(section="Diffusion Policy", ...)``.
Sampler latency (DDIM-10 vs DDPM-100 per chunk) is measured by ``benchmarks.bench_samplers``.
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import os
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.results import record
from coursekit.checkpoint import SHIPPED_DIR, CheckpointSaver, copy_checkpoint_half, load_checkpoint, read_checkpoint_info
from coursekit.data.episodes import EpisodeDataset
from coursekit.evaluate import evaluate_pusht, heldout_seeds
from coursekit.experts.pusht_planner import noise_tag, parse_action_noise
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies import make_policy
from coursekit.stats import mean_estimate, rate_estimate
from coursekit.train import TrainConfig, train

COMMAND = ".venv/bin/python -m benchmarks.bench_diffusion_policy"
SECTION = "Diffusion Policy"
ROOT = Path(__file__).resolve().parent.parent
SHIP = {"diffusion": SHIPPED_DIR / "pusht_diffusion_state", "regression": SHIPPED_DIR / "pusht_regression_state"}


def load_or_collect(path: Path, n_episodes: int, seed: int, action_noise: tuple[float, ...] = (0.0,)) -> EpisodeDataset:
    """The demonstrations file, collected with the PushT expert if it does not exist yet."""
    if path.is_file():
        return EpisodeDataset.load(path)
    from coursekit.experts.pusht_planner import collect_dataset

    dataset = collect_dataset(n_episodes, seed, action_noise=action_noise)
    dataset.save(path)
    return dataset


def throughput(dataset: EpisodeDataset, threads: int, seconds: float, batch_size: int,
               features: str = "pusht_state") -> float:
    """Samples/s of full trainer steps (CPU-default U-Net) after 5 warm-up steps."""
    policy, batches, _ = make_policy("diffusion", dataset, features=features, device="cpu", batch_size=batch_size)
    train(policy, batches, TrainConfig(max_steps=5, num_threads=threads, progress=False, batch_size=batch_size))
    result = train(policy, batches, TrainConfig(minutes=seconds / 60, num_threads=threads, progress=False,
                                                checkpoint_every_minutes=None, batch_size=batch_size))
    return float(result.summary["samples_per_s"])


def run_dir(kind: str, args: argparse.Namespace) -> Path:
    """Where ``kind``'s checkpoint for this budget/U-Net/batch/LR lives under --out (--reuse finds it there)."""
    return args.out / (f"{kind}_{args.minutes:g}min_{args.down_dims.replace(',', '-')}_b{args.batch_size}_lr{args.lr:g}"
                       + data_tag(args))


def data_tag(args: argparse.Namespace) -> str:
    """Name suffix for non-default demonstrations / observation features ('' for the defaults)."""
    feats = "" if args.features == "pusht_state" else "_" + args.features.removeprefix("pusht_")
    return noise_tag(args.action_noise) + feats


def train_policy(kind: str, dataset: EpisodeDataset, args: argparse.Namespace, out: Path) -> dict:
    """Train ``kind`` for the budget into ``out`` (unless it exists and --reuse); returns the training summary."""
    if args.reuse and (out / "config.json").is_file():
        return read_checkpoint_info(out)["training"]
    unet = UNet1DConfig(down_dims=tuple(int(v) for v in args.down_dims.split(",")))
    policy, batches, _ = make_policy(kind, dataset, features=args.features, seed=args.seed, device="cpu",
                                     batch_size=args.batch_size, unet=unet)
    meta = {**dataset.meta, "n_steps": dataset.n_steps}
    meta.pop("route_choices", None)  # bulky; the dataset file keeps it
    minutes = args.minutes if kind == "diffusion" or args.regression_minutes is None else args.regression_minutes
    threads, max_steps = args.threads, None
    if kind == "regression" and args.regression_steps is not None:
        # Step-matched baseline: exactly as many optimiser steps (and samples, LR schedule) as the
        # diffusion run, whatever the wall clock; the fairest comparison when the two ran on
        # different numbers of threads.
        max_steps, minutes = args.regression_steps, None
    if kind == "regression" and args.regression_threads is not None:
        threads = args.regression_threads
    cfg = TrainConfig(minutes=minutes, max_steps=max_steps, num_threads=threads, seed=args.seed, lr=args.lr,
                      batch_size=args.batch_size)
    return train(policy, batches, cfg, callbacks=[CheckpointSaver(out, dataset_meta=meta)]).summary


def evaluate_shipped(args: argparse.Namespace, rec) -> None:
    """Score the shipped checkpoints with notebook 05's sampler (DDIM-10) on the protocol seeds, with
    bootstrap intervals. DDPM-100 on the same 200 seeds is bench_claims' row ("DP DDPM-100 score, all
    starts"): ten times the cost for a figure the table already holds."""
    seeds = heldout_seeds(args.episodes)
    seed_range = f"{seeds[0]}-{seeds[-1]}"
    for kind in ("diffusion", "regression"):
        info = read_checkpoint_info(SHIP[kind])
        policy = load_checkpoint(SHIP[kind], device="cpu")
        t = info["training"]
        prior = t.get("init_from") or {}
        steps, minutes = t["steps"] + (prior.get("steps") or 0), (t["seconds"] + (prior.get("seconds") or 0)) / 60
        trained = f"trained {steps} steps / {minutes:.0f} min in all (batch {t['train_config']['batch_size']}, float16 weights)"
        sampler, n_steps = ("ddim", 10) if kind == "diffusion" else (None, None)
        t0 = time.perf_counter()
        r = evaluate_pusht(policy, seeds=seeds, sampler=sampler, num_inference_steps=n_steps,
                           dataset_meta=info["dataset"], progress=False)
        score, success = mean_estimate(r.max_reward), rate_estimate(np.asarray(r.success, dtype=bool))
        print(f"shipped {kind}: score {score}, success {success} ({trained}; {time.perf_counter() - t0:.0f} s)")
        name = "shipped checkpoint score, DDIM-10 (notebook 05)" if kind == "diffusion" else \
            "shipped regression checkpoint score (notebook 05)"
        rec(SECTION, name, round(score.value, 3), "", f"{COMMAND} --only shipped --episodes {args.episodes} --threads {args.threads}",
            target=">= 0.90" if kind == "diffusion" else "",
            note=f"success {success.value:.1%} (Wilson 95 % {success.lo:.1%}-{success.hi:.1%}); bootstrap 95 % interval; "
                 f"stderr {r.summary()['score_stderr']:.3f}; {args.episodes} held-out seeds from 100000, 300 steps; "
                 f"{trained}; evaluated with {torch.get_num_threads()} torch thread(s)",
            interval=(round(score.lo, 3), round(score.hi, 3)), n=score.n, seeds=seed_range)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line, checked; the recipe's lr and batch size filled in where not given."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=["throughput", "score", "shipped"], default=None,
                        help="run one part (shipped: evaluate coursekit/checkpoints/pusht_*_state as notebook 05 does)")
    parser.add_argument("--minutes", type=float, default=20.0, help="training budget per policy (default 20)")
    parser.add_argument("--threads", type=int, default=2, help="torch threads for training and evaluation (default 2)")
    parser.add_argument("--episodes", type=int, default=200, help="held-out evaluation episodes from 100000 (protocol, default 200)")
    parser.add_argument("--demos", type=int, default=400, help="demonstrations (default 400, seeds 0.. plus any the expert failed)")
    parser.add_argument("--action-noise", default="0,5",
                        help="DART execution noise of the expert demos in px, one level or a comma list cycled over "
                             "episodes (default 0,5: alternate clean and 5 px; 0 = clean demos only)")
    parser.add_argument("--features", choices=["pusht_state", "pusht_keypoints"], default="pusht_keypoints",
                        help="observation features (default pusht_keypoints, the paper's low-dim; pusht_state = "
                             "agent xy, block xy, sin/cos angle)")
    parser.add_argument("--regression-minutes", type=float, default=None,
                        help="training budget of the regression baseline (default: --minutes)")
    parser.add_argument("--regression-steps", default=None,
                        help="train the baseline for this many optimiser steps instead of minutes; 'match' = as many "
                             "as the diffusion checkpoint in --out (a step-matched comparison)")
    parser.add_argument("--regression-threads", type=int, default=None, help="torch threads of the baseline (default --threads)")
    parser.add_argument("--ddim-spacing", choices=["leading", "trailing"], default=None,
                        help="DDIM timestep spacing at evaluation (default: the checkpoint's config)")
    parser.add_argument("--policies", default="diffusion,regression", help="which to train/evaluate (default both)")
    parser.add_argument("--parallel", action="store_true",
                        help="train diffusion and regression at the same time, one thread each (half the wall-clock time)")
    parser.add_argument("--recipe", choices=["paper", "cpu"], default="cpu",
                        help="cpu (default): lr 5e-4, batch 128 for a 20-minute budget; paper: lr 1e-4, batch 256")
    parser.add_argument("--lr", type=float, default=None, help="peak learning rate (default: the recipe's)")
    parser.add_argument("--batch-size", type=int, default=None, help="batch size (default: the recipe's)")
    parser.add_argument("--down-dims", default="64,128,256", help="U-Net channels (default 64,128,256 = CPU default)")
    parser.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_dp", help="work directory")
    parser.add_argument("--reuse", action="store_true", help="reuse checkpoints already in --out (evaluate only)")
    parser.add_argument("--ship", action="store_true", help="copy the trained checkpoints to coursekit/checkpoints/")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.threads < 1:
        parser.error(f"--episodes and --threads must be >= 1, got --episodes {args.episodes} --threads {args.threads}")
    args.action_noise = parse_action_noise(args.action_noise)
    base = TrainConfig.recipe(args.recipe, max_steps=1)
    args.lr = args.lr if args.lr is not None else base.lr
    args.batch_size = args.batch_size if args.batch_size is not None else base.batch_size
    return args


def part_throughput(args: argparse.Namespace, dataset, rec, machine: str) -> None:
    """Training samples/s of the CPU default U-Net at batch 256 and at ``--batch-size`` (rows)."""
    for bs in sorted({256, args.batch_size}):
        sps = throughput(dataset, args.threads, seconds=60.0, batch_size=bs, features=args.features)
        print(f"training throughput, batch {bs}: {sps:.0f} samples/s")
        rec(SECTION, f"training throughput (CPU default U-Net, batch {bs})", round(sps), "samples/s",
            f"{COMMAND} --only throughput",
            note=f"U-Net 64/128/256 (4.5 M params), full trainer step incl. EMA; 60 s after warm-up; {machine}")


def resolve_regression_steps(args: argparse.Namespace) -> None:
    """``--regression-steps match``: as many optimiser steps as the diffusion checkpoint in ``--out``."""
    if args.regression_steps == "match":
        dp_dir = run_dir("diffusion", args)
        if not (dp_dir / "config.json").is_file():
            raise FileNotFoundError(f"--regression-steps match needs the diffusion checkpoint {str(dp_dir)!r}; "
                                    f"train it first (--policies diffusion)")
        args.regression_steps = int(read_checkpoint_info(dp_dir)["training"]["steps"])
        print(f"regression baseline: {args.regression_steps} optimiser steps, as many as {dp_dir.name}")
    elif args.regression_steps is not None:
        args.regression_steps = int(args.regression_steps)


def train_in_parallel(args: argparse.Namespace, dataset, outs: dict[str, Path]) -> dict[str, dict]:
    """Both trainings at once, one torch thread (one core) each: half the wall-clock time."""
    one = argparse.Namespace(**{**vars(args), "threads": 1})
    ctx = multiprocessing.get_context("spawn")
    side = ctx.Process(target=train_policy, args=("regression", dataset, one, outs["regression"]))
    side.start()
    summaries = {"diffusion": train_policy("diffusion", dataset, one, outs["diffusion"])}
    side.join()
    if side.exitcode != 0:
        raise RuntimeError(f"the regression training process failed (exit code {side.exitcode})")
    summaries["regression"] = read_checkpoint_info(outs["regression"])["training"]
    return summaries


def evaluate_trained(kind: str, out: Path, summary: dict, args: argparse.Namespace) -> None:
    """Print the held-out score of one trained (and, with ``--ship``, shipped) checkpoint, per sampler."""
    if args.ship:  # ship float16 weights (half the size) and evaluate exactly what is shipped
        out = copy_checkpoint_half(out, SHIP[kind])
    policy = load_checkpoint(out, device="cpu")
    dataset_meta = read_checkpoint_info(out)["dataset"]
    if args.ddim_spacing is not None and kind == "diffusion":
        policy.config = dataclasses.replace(policy.config, ddim_timestep_spacing=args.ddim_spacing)
    samplers = [("ddim", 10), ("ddpm", 100)] if kind == "diffusion" else [(None, None)]
    for sampler, steps in samplers:
        t0 = time.perf_counter()
        r = evaluate_pusht(policy, n_episodes=args.episodes, sampler=sampler, num_inference_steps=steps,
                           dataset_meta=dataset_meta)
        label = f"{kind} {sampler.upper()}-{steps}" if sampler else kind
        print(f"{label}: score {r.score:.3f} +- {r.summary()['score_stderr']:.3f}, success {r.success_rate:.0%}, "
              f"{summary['steps']} steps in {summary['seconds']:.0f} s, eval {time.perf_counter() - t0:.0f} s")


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.threads)
    load = os.getloadavg()[0]
    rec = (lambda *a, **k: None) if args.no_record else record  # noqa: E731
    if args.only == "shipped":  # needs no demonstrations: do not collect 400 of them first
        evaluate_shipped(args, rec)
        return
    dataset = load_or_collect(args.out / f"pusht_{args.demos}ep_seed0{noise_tag(args.action_noise)}.npz", args.demos, 0,
                              args.action_noise)
    if args.only in (None, "throughput"):
        part_throughput(args, dataset, rec, f"this command ran with {args.threads} torch thread(s), load average "
                                            f"{load:.1f} at its start")
    if args.only == "throughput":
        return

    kinds = [k.strip() for k in args.policies.split(",") if k.strip()]
    if not set(kinds) <= {"diffusion", "regression"}:
        raise ValueError(f"--policies must name diffusion and/or regression, got {args.policies!r}")
    budgets = [args.minutes if k == "diffusion" else (args.regression_minutes or args.minutes) for k in kinds]
    budget = max(budgets) if args.parallel else sum(budgets)
    print(f"training {kinds} for {budget:g} min in all, plus evaluation on {args.episodes} episodes "
          f"(DDPM-100 costs ten times DDIM-10)")
    outs = {k: run_dir(k, args) for k in kinds}
    resolve_regression_steps(args)
    summaries = train_in_parallel(args, dataset, outs) if args.parallel and len(kinds) == 2 else {}
    for kind in kinds:
        summary = summaries.get(kind) or train_policy(kind, dataset, args, outs[kind])
        evaluate_trained(kind, outs[kind], summary, args)

    # Printed, not recorded: a minutes budget on one training seed is no protocol figure
    # (bench_chunk_ablation's step-budget curve over 3 training seeds is).
    print("score part: printed only, not written to results.json (see bench_chunk_ablation for the budget curve)")


if __name__ == "__main__":
    main()
