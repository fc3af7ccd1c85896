"""ACT benchmarks: chunk latency vs Diffusion Policy, and trained success on both ALOHA tasks and PushT.

Run everything (several hours on 2 cores: four 30-minute trainings plus evaluations)::

    .venv/bin/python -m benchmarks.bench_act
    .venv/bin/python -m benchmarks.bench_act --only latency             # ~1 minute
    .venv/bin/python -m benchmarks.bench_act --only cube --minutes 30   # train + evaluate ACT on transfer cube
    .venv/bin/python -m benchmarks.bench_act --only cube --checkpoint coursekit/checkpoints/act_transfer_cube --threads 1
    .venv/bin/python -m benchmarks.bench_act --only act_pusht --checkpoint coursekit/checkpoints/act_pusht --threads 1
    .venv/bin/python -m benchmarks.bench_act --quick --no-record        # smoke run of every section

Sections (``--only`` takes several):

- ``latency``: batch-1 chunk latency of ACT (CPU default, k = 100, Da = 14) and Diffusion Policy
  with DDIM-10 (CPU U-Net, To = 2, Tp = 16, Da = 14), alternating in one run (median of repeats),
  plus the paper-size ACT; per-action cost with each one's executor (ACT + temporal ensembling
  queries every step; DP executes Ta = 8 per chunk). Random weights: latency does not depend on them.
- ``cube`` / ``insertion``: 50 scripted demonstrations (seeds 0..49), ACT trained for ``--minutes``
  on ``--threads`` threads (or ``--checkpoint``), then the held-out episodes with temporal ensembling
  on (m = 0.01) and off (open-loop chunks of k); per-stage rates and strict (final-state) success.
  Only a given ``--checkpoint`` is recorded: a minutes budget on a shared machine is not a
  reproducible condition (the step-budget, 3-training-seed sweep is ``bench_act_chunks``).
- ``dp_cube``: Diffusion Policy (state features, DDIM-10, receding horizon Ta = 8) on transfer cube.
- ``act_pusht``: ACT (k = 20, temporal ensembling) on PushT state features (trained, or
  ``--checkpoint``), evaluated by the PushT protocol (mean-of-max coverage score, success rate).

Evaluation follows the protocol: ``--episodes`` (default 200) held-out seeds from 100000, every
rate with its Wilson 95 % interval and every mean score with a bootstrap one (:mod:`coursekit.stats`),
recorded with ``n`` and ``seeds``. Every figure goes through ``benchmarks.results.record(section="ACT", ...)``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks.results import record
from coursekit.checkpoint import SHIPPED_DIR
from coursekit.evaluate.result import EVAL_SEED_START
from coursekit.stats import Estimate, mean_estimate, rate_estimate

COMMAND = ".venv/bin/python -m benchmarks.bench_act"
SECTION = "ACT"
SECTIONS = ("latency", "cube", "insertion", "dp_cube", "act_pusht")
TASK_LABEL = {"transfer_cube": "transfer cube", "insertion": "insertion"}


def _seeds_text(n: int) -> str:
    """The protocol seed range of an n-episode evaluation, as results rows give it."""
    return f"{EVAL_SEED_START}-{EVAL_SEED_START + n - 1}"


def _strict(r: Any) -> Estimate:
    """Strict (final-state) success of an arm-pair evaluation with its Wilson interval: the recorded
    states' column 1 on the last step (``coursekit.tasks.aloha.arm_pair_scores``)."""
    return rate_estimate(np.asarray(r.states[:, -1, 1] > 0.5, dtype=bool))


def _record_pct(name: str, est: Estimate, cmd: str, target: str, note: str) -> None:
    """Record a success rate in percent, with its Wilson interval, n and protocol seeds."""
    record(SECTION, name, round(100 * est.value, 1), "%", cmd, target=target, note=note,
           interval=(round(100 * est.lo, 1), round(100 * est.hi, 1)), n=est.n, seeds=_seeds_text(est.n))


def _median_ms(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def bench_latency(args: argparse.Namespace) -> None:
    """Batch-1 chunk latency, ACT vs DP DDIM-10, alternating repeats in one run."""
    from coursekit.data.normalize import MeanStdNormalizer, MinMaxNormalizer
    from coursekit.policies.act import ACTConfig, ACTPolicy
    from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig

    Do, Da = 21, 14
    if args.latency_threads:
        torch.set_num_threads(args.latency_threads)
    torch.manual_seed(0)
    act = ACTPolicy(ACTConfig(obs_dim=Do, action_dim=Da), {"obs": MeanStdNormalizer(np.zeros(Do), np.ones(Do)),
                                                           "action": MeanStdNormalizer(np.zeros(Da), np.ones(Da))}).eval()
    act_paper = ACTPolicy(ACTConfig.paper(obs_dim=Do, action_dim=Da), dict(act.normalizers)).eval()
    dp = DiffusionPolicy(DiffusionPolicyConfig(features="aloha_state", obs_dim=Do, action_dim=Da),
                         {"obs": MinMaxNormalizer(-np.ones(Do), np.ones(Do)),
                          "action": MinMaxNormalizer(-np.ones(Da), np.ones(Da))}).eval()
    act_obs, dp_obs = torch.zeros(1, 1, Do), torch.zeros(1, dp.config.n_obs_steps, Do)
    g = torch.Generator().manual_seed(0)
    runs = {"act": lambda: act.predict_chunk(act_obs), "act_paper": lambda: act_paper.predict_chunk(act_obs),
            "dp": lambda: dp.predict_chunk(dp_obs, generator=g)}
    for fn in runs.values():  # warm-up
        for _ in range(2):
            fn()
    times: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(args.repeats):
        for name, fn in runs.items():
            times[name] += _median_ms(fn, 1)
    med = {k: statistics.median(v) for k, v in times.items()}
    ratio = med["dp"] / med["act"]
    ta = dp.config.n_action_steps
    print(f"ACT cpu ({act.num_parameters() / 1e6:.2f} M, k={act.config.chunk_size}): {med['act']:.1f} ms/chunk; "
          f"ACT paper ({act_paper.num_parameters() / 1e6:.1f} M): {med['act_paper']:.1f} ms; "
          f"DP DDIM-10 ({dp.num_parameters() / 1e6:.2f} M, Tp={dp.config.horizon}): {med['dp']:.1f} ms; "
          f"DP/ACT = {ratio:.1f}x; threads {torch.get_num_threads()}")
    if args.no_record:
        return
    note = (f"batch 1, Do={Do}, Da={Da}, median of {args.repeats} alternating repeats in one run, random weights, "
            f"{torch.get_num_threads()} torch threads")
    record(SECTION, "ACT chunk latency (batch 1, cpu size, k=100)", round(med["act"], 2), "ms", f"{COMMAND} --only latency",
           note=f"{act.num_parameters() / 1e6:.2f} M params; " + note)
    record(SECTION, "ACT chunk latency (batch 1, paper size)", round(med["act_paper"], 1), "ms", f"{COMMAND} --only latency",
           note=f"{act_paper.num_parameters() / 1e6:.1f} M params (no backbone); " + note)
    record(SECTION, "DP DDIM-10 chunk latency (batch 1, same run)", round(med["dp"], 1), "ms", f"{COMMAND} --only latency",
           note=f"cpu U-Net {dp.num_parameters() / 1e6:.2f} M, To=2, Tp=16; " + note)
    record(SECTION, "DP DDIM-10 / ACT chunk latency", round(ratio, 1), "x", f"{COMMAND} --only latency", target=">= 5x",
           note="same run; " + note)
    record(SECTION, "ms per action: ACT + temporal ensembling vs DP (Ta=8)",
           f"{med['act']:.1f} vs {med['dp'] / ta:.1f}", "ms", f"{COMMAND} --only latency",
           note="ensembling queries ACT every step (1 chunk per action); DP re-plans every Ta = 8 steps")


def _dataset(task: str, args: argparse.Namespace):
    """50 scripted demonstrations (cached under --data-dir)."""
    from coursekit.data import EpisodeDataset

    n = 5 if args.quick else 50
    path = Path(args.data_dir) / f"aloha_{task}_{n}ep_seed0.npz"
    if path.exists():
        return EpisodeDataset.load(path)
    from coursekit.tasks import get_task

    ds = get_task(task).collect(n, 0, progress=not args.no_progress)
    ds.save(path)
    return ds


def _train(policy: Any, batches: Any, config: Any, out: Path, meta: dict[str, Any]) -> dict[str, Any]:
    from coursekit.checkpoint import CheckpointSaver
    from coursekit.train import train

    result = train(policy, batches, config, callbacks=[CheckpointSaver(out, dataset_meta=meta)])
    return result.summary


def _load_or_train_act(task: str, args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    from coursekit.checkpoint import load_checkpoint, read_checkpoint_info
    from coursekit.policies import make_policy
    from coursekit.train import TrainConfig

    if args.checkpoint:
        return load_checkpoint(args.checkpoint, device="cpu"), read_checkpoint_info(args.checkpoint)["training"]
    ds = _dataset(task, args)
    policy, batches, recipe = make_policy("act", ds, recipe="cpu", seed=args.seed)  # batch 16
    config = TrainConfig(**recipe, minutes=args.minutes, num_threads=args.threads, progress=not args.no_progress,
                         checkpoint_every_minutes=5.0)
    out = Path(args.ckpt_dir) / f"act_{task}"
    summary = _train(policy, batches, config, out, {**ds.meta, "n_steps": ds.n_steps})
    print(f"trained ACT on {task}: {json.dumps({k: summary[k] for k in ('steps', 'seconds', 'final_loss')})} -> {out}")
    return load_checkpoint(out, device="cpu"), summary


def _trained_text(summary: dict[str, Any]) -> str:
    """'<steps> steps / <min> min on <t> thread(s)[, warm-started from ...]' of a checkpoint's training summary."""
    trained = (f"{summary.get('steps')} steps / {(summary.get('seconds') or 0) / 60:.1f} min on "
               f"{summary.get('torch_threads')} thread(s)")
    prior = summary.get("init_from")
    if prior:
        trained += f", warm-started from {prior.get('steps')} steps / {(prior.get('seconds') or 0) / 60:.1f} min"
    return trained


def bench_aloha_act(task: str, args: argparse.Namespace) -> None:
    """Train (or load) ACT on an ALOHA task; evaluate with temporal ensembling on and off. Only a
    given --checkpoint is recorded: a minutes budget shared with other jobs does not reproduce."""
    from coursekit.evaluate import evaluate_aloha
    from coursekit.execution.ensembling import TemporalEnsemble
    from coursekit.execution.receding import RecedingHorizon

    policy, summary = _load_or_train_act(task, args)
    n = 3 if args.quick else args.episodes
    k = policy.config.chunk_size
    executors = {"temporal ensembling m=0.01": lambda pc: TemporalEnsemble(pc, 1, ensemble_decay=0.01),
                 f"open-loop chunks (Ta=k={k})": lambda pc: RecedingHorizon(pc, 1, k)}
    label = TASK_LABEL[task]
    shipped = args.checkpoint is not None and Path(args.checkpoint).resolve().parent == SHIPPED_DIR
    source, targets = (("shipped checkpoint", {"transfer_cube": ">= 90 %", "insertion": ">= 40 %"}) if shipped
                       else (f"checkpoint {args.checkpoint}", {}))
    for name, factory in executors.items():
        torch.set_num_threads(args.threads)
        r = evaluate_aloha(policy, task, n_episodes=n, executor_factory=factory, progress=not args.no_progress,
                           max_steps=60 if args.quick else 400)
        rates, strict = r.info["stage_rates"], _strict(r)
        print(f"ACT {label} ({source if args.checkpoint else 'just trained'}), {name}: strict {strict}, stages "
              f"{[round(rates[s], 2) for s in range(1, 5)]}, {r.ms_per_chunk:.1f} ms/chunk (batch {n})")
        if args.no_record or args.checkpoint is None:
            continue
        note = (f"{n} held-out episodes (seeds {_seeds_text(n)}), Wilson 95 % interval; stages 1-4 reached "
                f"(stage 4 = published success): {', '.join(f'{rates[s]:.2f}' for s in range(1, 5))}; "
                f"trained {_trained_text(summary)}; evaluated with {args.threads} torch thread(s)")
        target = targets.get(task, "") if name.startswith("temporal") else ""
        cmd = (f"{COMMAND} --only {'cube' if task == 'transfer_cube' else 'insertion'} --checkpoint {args.checkpoint} "
               f"--episodes {n} --threads {args.threads}")
        _record_pct(f"ACT {label} strict success, {source}, {name}", strict, cmd, target, note)
    if args.checkpoint is None and not args.no_record:
        print("not recorded: only a --checkpoint's evaluation is a results row (bench_act_chunks: step budgets)")


def _maybe_ship(out: Path, name: str, args: argparse.Namespace) -> tuple[Path, str]:
    """With --ship, copy the trained checkpoint to coursekit/checkpoints/<name> as float16 and return
    that copy (so the recorded figure is exactly what notebook 09 and `coursekit eval` load)."""
    if not args.ship:
        return out, ""
    from coursekit.checkpoint import copy_checkpoint_half

    return copy_checkpoint_half(out, SHIPPED_DIR / name), f"; evaluated: the shipped float16 copy coursekit/checkpoints/{name}"


def bench_dp_cube(args: argparse.Namespace) -> None:
    """Diffusion Policy on transfer cube with the same state features, receding horizon."""
    from coursekit.checkpoint import load_checkpoint, read_checkpoint_info
    from coursekit.evaluate import evaluate_aloha
    from coursekit.policies import make_policy
    from coursekit.train import TrainConfig

    if args.checkpoint:  # re-evaluate a trained checkpoint (e.g. the shipped one) without training
        out, shipped = Path(args.checkpoint), f"; evaluated: {args.checkpoint}"
        summary = read_checkpoint_info(out)["training"]
    else:
        ds = _dataset("transfer_cube", args)
        policy, batches, recipe = make_policy("diffusion", ds, features="aloha_state", recipe="cpu", seed=args.seed)
        out = Path(args.ckpt_dir) / "dp_transfer_cube"
        summary = _train(policy, batches, TrainConfig(**recipe, minutes=args.minutes, num_threads=args.threads,
                                                      progress=not args.no_progress), out, ds.meta)
        out, shipped = _maybe_ship(out, "dp_transfer_cube", args)
    policy = load_checkpoint(out, device="cpu")
    n = 3 if args.quick else args.episodes
    r = evaluate_aloha(policy, "transfer_cube", n_episodes=n, progress=not args.no_progress,
                       max_steps=60 if args.quick else 400)
    rates, strict = r.info["stage_rates"], _strict(r)
    print(f"DP transfer cube: strict {strict}, stages {[rates[s] for s in range(1, 5)]}")
    if not args.no_record:
        cmd = f"{COMMAND} --only dp_cube " + (f"--checkpoint {args.checkpoint}" if args.checkpoint else
                                             f"--minutes {args.minutes:g}" + (" --ship" if args.ship else ""))
        _record_pct("DP transfer cube success (strict, DDIM-10, Ta=8)", strict, f"{cmd} --episodes {n} --threads {args.threads}",
                    "", f"{n} held-out episodes (seeds {_seeds_text(n)}), Wilson 95 % interval; stages 1-4: "
                        f"{', '.join(f'{rates[s]:.2f}' for s in range(1, 5))}; trained {_trained_text(summary)} (cpu recipe), "
                        f"state features [qpos, cube pose]" + (f"; {args.note_concurrent}" if args.note_concurrent else "")
                        + shipped)


def _train_act_pusht(args: argparse.Namespace) -> tuple[Path, dict[str, Any], str]:
    """Train ACT (k = 20) on 200 PushT expert demonstrations for --minutes; (checkpoint, summary, shipped note)."""
    from coursekit.data import EpisodeDataset
    from coursekit.policies import make_policy
    from coursekit.train import TrainConfig

    n_demo = 10 if args.quick else 200
    path = Path(args.data_dir) / f"pusht_{n_demo}ep_seed0.npz"
    if path.exists():
        ds = EpisodeDataset.load(path)
    else:
        from coursekit.experts.pusht_planner import collect_dataset

        ds = collect_dataset(n_demo, 0, progress=not args.no_progress)
        ds.save(path)
    policy, batches, recipe = make_policy("act", ds, features="pusht_state", recipe="cpu", seed=args.seed, chunk_size=20)
    out = Path(args.ckpt_dir) / "act_pusht"
    summary = _train(policy, batches, TrainConfig(**recipe, minutes=args.minutes, num_threads=args.threads,
                                                  progress=not args.no_progress), out, ds.meta)
    out, shipped = _maybe_ship(out, "act_pusht", args)
    return out, summary, shipped


def bench_act_pusht(args: argparse.Namespace) -> None:
    """ACT on PushT state features (k = 20, temporal ensembling), PushT protocol; trained, or --checkpoint."""
    from coursekit.checkpoint import load_checkpoint, read_checkpoint_info
    from coursekit.evaluate import evaluate_pusht

    if args.checkpoint:
        out, shipped = Path(args.checkpoint), f"; evaluated: {args.checkpoint}"
        summary = read_checkpoint_info(out)["training"]
    else:
        out, summary, shipped = _train_act_pusht(args)
    policy = load_checkpoint(out, device="cpu")
    n = 3 if args.quick else args.episodes
    r = evaluate_pusht(policy, n_episodes=n, dataset_meta=read_checkpoint_info(out)["dataset"],
                       progress=not args.no_progress, max_steps=30 if args.quick else 300)
    score, success = mean_estimate(r.max_reward), rate_estimate(np.asarray(r.success, dtype=bool))
    print(f"ACT PushT: score {score}, success {success}")
    if args.no_record:
        return
    demos = read_checkpoint_info(out)["dataset"].get("n_episodes")
    note = (f"{n} held-out seeds ({_seeds_text(n)}), bootstrap 95 % interval; success {success.value:.1%} "
            f"(Wilson 95 % {success.lo:.1%}-{success.hi:.1%}); k=20, temporal ensembling m=0.01; trained "
            f"{_trained_text(summary)}, {demos} expert demos" + (f"; {args.note_concurrent}" if args.note_concurrent else "")
            + shipped)
    cmd = f"{COMMAND} --only act_pusht " + (f"--checkpoint {args.checkpoint}" if args.checkpoint else
                                            f"--minutes {args.minutes:g}" + (" --ship" if args.ship else ""))
    record(SECTION, "ACT PushT score (mean of max coverage)", round(score.value, 3), "",
           f"{cmd} --episodes {n} --threads {args.threads}", note=note,
           interval=(round(score.lo, 3), round(score.hi, 3)), n=n, seeds=_seeds_text(n))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=SECTIONS, default=list(SECTIONS), help="sections to run")
    parser.add_argument("--minutes", type=float, default=30.0, help="training budget per policy (default 30)")
    parser.add_argument("--threads", type=int, default=2, help="torch threads for training and evaluation (default 2)")
    parser.add_argument("--episodes", type=int, default=200, help="held-out evaluation episodes (protocol, default 200)")
    parser.add_argument("--repeats", type=int, default=15, help="latency repeats (default 15)")
    parser.add_argument("--latency-threads", type=int, default=None, help="torch threads for the latency section (default: torch's)")
    parser.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    parser.add_argument("--checkpoint", default=None, help="evaluate this checkpoint instead of training (cube, insertion, act_pusht: ACT; dp_cube: Diffusion Policy)")
    parser.add_argument("--data-dir", default="outputs/data", help="where demonstrations are cached")
    parser.add_argument("--ckpt-dir", default="outputs/checkpoints", help="where trained checkpoints are written")
    parser.add_argument("--ship", action="store_true",
                        help="dp_cube / act_pusht: copy the trained checkpoint into coursekit/checkpoints/ (float16) "
                             "and evaluate that copy")
    parser.add_argument("--note-concurrent", default="",
                        help="say in the notes what else ran on the machine during a 1-thread training (honesty)")
    parser.add_argument("--quick", action="store_true", help="tiny data/budgets: a smoke run of the script, not a measurement")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")
    parser.add_argument("--no-progress", action="store_true", help="hide progress bars")
    args = parser.parse_args(argv)
    if args.quick and args.ship:
        parser.error("--ship with --quick would ship a smoke-run model over coursekit/checkpoints/; drop one of them")
    if args.ship and args.checkpoint:
        parser.error("--ship copies a freshly trained model; with --checkpoint nothing is trained: drop one of them")
    if args.episodes < 1 or args.threads < 1:
        parser.error(f"--episodes and --threads must be >= 1, got --episodes {args.episodes} --threads {args.threads}")
    if args.quick:
        args.minutes = min(args.minutes, 0.5)
        args.repeats = min(args.repeats, 3)
    Path(args.data_dir).mkdir(parents=True, exist_ok=True)
    for section in args.only:
        t0 = time.perf_counter()
        if section != "latency":  # evaluations run on --threads (the latency section has its own setting)
            torch.set_num_threads(args.threads)
        if section == "latency":
            bench_latency(args)
        elif section == "cube":
            bench_aloha_act("transfer_cube", args)
        elif section == "insertion":
            bench_aloha_act("insertion", args)
        elif section == "dp_cube":
            bench_dp_cube(args)
        elif section == "act_pusht":
            bench_act_pusht(args)
        print(f"-- {section} done in {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
