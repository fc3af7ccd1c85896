"""Compounding error on the arm pair: ACT's chunk size k swept, and ACT without its CVAE.

The second claim of the text (§10.2): predicting a chunk of k actions and executing it shortens
the effective horizon of the task by k, which dampens the compounding error of a single-step
policy (ACT, Zhao et al. 2023, Sec. 3.3; its Fig. 8a: success collapses at k = 1 on the simulated
tasks). And "ACT uses its latent lightly": the same network without the CVAE encoder (z absent,
the L1 loss alone; ACT's own ablation, Sec. 5) on the same protocol.

    .venv/bin/python -m benchmarks.bench_act_chunks --steps 7000 --train-seeds 0 1 2 --threads 1
    .venv/bin/python -m benchmarks.bench_act_chunks --steps 20 --train-seeds 0 --episodes 2 --variants "ACT k=10" --no-record  # smoke
    .venv/bin/python -m benchmarks.bench_act_chunks --steps 7000 --train-seeds 0 --threads 1 --variants "ACT k=100 from the top camera"
    .venv/bin/python -m benchmarks.bench_act_chunks --task insertion --steps 7000 --train-seeds 0 1 2 --threads 1

Every variant (:data:`VARIANTS`) is ACT with the "cpu" recipe on the same 50 scripted
demonstrations of ``--task`` (seeds 0-49; the transfer cube unless told, the insertion is the second
task of the ACT paper's sweep), the same step budget (the shipped ACT transfer-cube checkpoint trained
7173 steps in all), each training seed of ``--train-seeds``; evaluated on the
protocol seeds (100000-100199) with two executors: open-loop chunks (Ta = k: the k actions of a
chunk executed before the next observation, the setting of the paper's k sweep) and temporal
ensembling (m = 0.01, ACT's own executor). At k = 1 the two are the same single-step policy, so
only the first is run. A row per (variant, executor): strict success pooled over training seeds
(n = seeds x episodes) with a Wilson 95 % interval, the per-seed rates and a t-interval over
training seeds in the note.

Runs and evaluations are cached under ``--out`` (never the repository) and resume: training from
its state file (``coursekit.train_state``, rewritten every minute), evaluation per block of 50 seeds.
Each run is evaluated as soon as it is trained, and a run whose evaluations are all kept in the
ledger (``python -m benchmarks.ledger``) is neither trained nor loaded: rows over three training
seeds can be recorded on a machine that trained none of them.
"""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path

import numpy as np

from benchmarks.protocol import add_protocol_args, protocol_seeds, t_estimate
from benchmarks.resumable import cache_dir, evaluation_file, run_slug
from coursekit.atomic import atomic_write_text
from coursekit.tasks import INSERTION, TRANSFER_CUBE

SECTION = "Chunk ablation (arm pair)"
COMMAND = ".venv/bin/python -m benchmarks.bench_act_chunks"
TASKS = (TRANSFER_CUBE.name, INSERTION.name)
"""The arm pair's tasks (``coursekit.tasks`` names); the first is the default, and its runs and rows carry no task name."""
N_DEMOS = 50
VARIANTS = {  # name -> ACT config fields
    "ACT k=1": {"chunk_size": 1},
    "ACT k=10": {"chunk_size": 10},
    "ACT k=25": {"chunk_size": 25},
    "ACT k=100": {"chunk_size": 100},
    "ACT k=100 without CVAE": {"chunk_size": 100, "use_vae": False},
    "ACT k=100 from the top camera": {"chunk_size": 100, "features": "aloha_image", "vision": "arm_pair"},
}
SWEEP = [name for name in VARIANTS if "camera" not in name]
"""The default variants: the k sweep and the no-CVAE run (the camera run, chapter 12's stretch, is asked for by name:
ACT seeing the 96 x 128 "top" camera frame rendered from the stored states, plus qpos: the "arm_pair" vision
preset, narrow widths without crops, as ACT trains)."""
EXECUTORS = ("open-loop chunks (Ta=k)", "temporal ensembling m=0.01")
BLOCK = 50
"""Seeds per cached evaluation block (the unit an interrupted evaluation resumes from)."""
EPISODE_STEPS: int | None = None
"""Control steps per evaluation episode: None is the protocol's (8 s); tests shorten it."""
CACHE = cache_dir("act_chunks")


def demonstrations(out: Path, task: str = TASKS[0]):
    """The 50 scripted demonstrations of ``task`` (seeds 0-49), collected once into ``out``."""
    from coursekit.data import EpisodeDataset
    from coursekit.tasks import get_task

    path = out / f"aloha_{task}_{N_DEMOS}ep_seed0.npz"
    if path.exists():
        return EpisodeDataset.load(path)
    ds = get_task(task).collect(N_DEMOS, 0, progress=False)
    ds.save(path)
    return ds


def run_dir(out: Path, name: str, ts: int, steps: int, task: str = TASKS[0]) -> Path:
    """The cache folder of variant ``name`` on ``task``, training seed ``ts``, ``steps`` optimiser steps.

    The transfer cube's folders carry no task (they were named before the insertion ran, and the
    ledger keeps them under those names): ``act-k-10_seed0_s7000`` vs ``act-k-10_insertion_seed0_s7000``.
    """
    on = "" if task == TASKS[0] else f"_{task}"
    return out / f"{run_slug(name)}{on}_seed{ts}_s{steps}"


def label(name: str, task: str) -> str:
    """The variant's name in its rows: "ACT k=10", or "ACT k=10 on insertion" on the second task."""
    return name if task == TASKS[0] else f"{name} on {task}"


def task_args(task: str) -> list[str]:
    """The command-line words that choose ``task``: none for the default (so its rows' commands stay as recorded)."""
    return [] if task == TASKS[0] else ["--task", task]


def train_or_load(name: str, ts: int, args: argparse.Namespace, dataset):
    """The variant ``name`` trained with seed ``ts`` for ``--steps`` (resumed or loaded from ``--out``)."""
    from benchmarks.resumable import load_or_train
    from coursekit.policies import make_policy

    fields = dict(VARIANTS[name])
    if "vision" in fields:
        from coursekit.nn.vision import VisionEncoderConfig

        fields["vision"] = VisionEncoderConfig.preset(fields["vision"])
    build = lambda: make_policy("act", dataset, recipe="cpu", seed=ts, **fields)  # noqa: E731
    run = run_dir(args.out, name, ts, args.steps, args.task)
    return load_or_train(run, build, args.steps, ts, args.threads, dataset.meta)


def executor_factory(executor: str, k: int):
    from coursekit.execution.ensembling import TemporalEnsemble
    from coursekit.execution.receding import RecedingHorizon

    if executor == EXECUTORS[0]:
        return lambda predict_chunk: RecedingHorizon(predict_chunk, 1, k)
    return lambda predict_chunk: TemporalEnsemble(predict_chunk, 1, ensemble_decay=0.01)


def evaluate_run(load, run: Path, executor: str, seeds: list[int], k: int, dataset, task: str = TASKS[0]) -> dict:
    """Strict success and highest stage per seed of ``run``, in cached blocks of ``BLOCK`` seeds.

    ``load()`` gives the trained policy (chunk size ``k``) and ``dataset()`` its demonstrations; either
    is called only when a block is neither kept in the ledger nor cached.
    """
    from coursekit.evaluate import evaluate_aloha

    tag = "open" if executor == EXECUTORS[0] else "te"
    out = {"seed": [], "strict": [], "stage": [], "seconds": 0.0}
    for i in range(0, len(seeds), BLOCK):
        block = seeds[i:i + BLOCK]
        path = evaluation_file(run, f"eval_{tag}_{block[0]}_{len(block)}.json")
        if not path.exists():
            r = evaluate_aloha(load(), task, seeds=block, executor_factory=executor_factory(executor, k),
                               dataset_meta=dataset().meta, progress=False, max_steps=EPISODE_STEPS)
            part = {"seed": block, "strict": (r.states[:, -1, 1] > 0.5).tolist(),
                    "stage": r.states[:, :, 0].max(axis=1).astype(int).tolist(), "seconds": r.seconds}
            atomic_write_text(path, json.dumps(part))  # a killed run leaves no half-written block
        part = json.loads(path.read_text())
        for key in ("seed", "strict", "stage"):
            out[key] += part[key]
        out["seconds"] += part["seconds"]
    return out


def summarise(name: str, executor: str, per_seed: dict[int, dict], args: argparse.Namespace, record) -> None:
    """One row: strict success pooled over training seeds, Wilson interval; per-seed rates in the note."""
    from coursekit.stats import wilson_interval

    strict = np.concatenate([np.asarray(e["strict"], dtype=bool) for e in per_seed.values()])
    rates = [float(np.mean(e["strict"])) for e in per_seed.values()]
    lo, hi = wilson_interval(int(strict.sum()), strict.size)
    _, tlo, thi = t_estimate(rates)
    stages = np.concatenate([e["stage"] for e in per_seed.values()])
    seeds = sorted(per_seed)
    note = (f"training seeds {seeds} (per seed: {', '.join(f'{100 * r:.1f} %' for r in rates)}; t-interval over "
            f"seeds [{100 * tlo:.1f}, {100 * thi:.1f}] %); {len(strict) // len(seeds)} protocol seeds each; stages 1-4 "
            f"reached: {', '.join(f'{np.mean(stages >= s):.2f}' for s in range(1, 5))}; {N_DEMOS} scripted "
            f"{args.task.replace('_', ' ')} demos, recipe cpu, {args.steps} steps, {args.threads} thread(s)")
    print(f"{label(name, args.task)}, {executor}: {100 * strict.mean():.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] (n={strict.size}); {note}")
    cmd = (f"{' '.join([COMMAND, *task_args(args.task)])} --steps {args.steps} --train-seeds {' '.join(map(str, seeds))} --threads {args.threads} "
           f"--variants '{name}'")
    record(SECTION, f"{label(name, args.task)}, {executor}: strict success", round(100 * float(strict.mean()), 1), "%", cmd,
           interval=[round(100 * lo, 1), round(100 * hi, 1)], n=int(strict.size), note=note,
           seeds=f"{min(e['seed'][0] for e in per_seed.values())}-{max(e['seed'][-1] for e in per_seed.values())}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=7000, help="optimiser steps per run (step-matched)")
    parser.add_argument("--train-seeds", type=int, nargs="+", default=[0, 1, 2], help="training seeds per variant")
    parser.add_argument("--variants", nargs="+", default=SWEEP, help=f"of {list(VARIANTS)} (default: the first {len(SWEEP)})")
    parser.add_argument("--task", choices=TASKS, default=TASKS[0], help="the arm pair's task (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=CACHE, help="runs and evaluations (resumable)")
    add_protocol_args(parser)
    args = parser.parse_args(argv)
    bad = [v for v in args.variants if v not in VARIANTS]
    if bad or args.steps < 1:
        raise SystemExit(f"bad --variants {bad} (expected some of {list(VARIANTS)}) or --steps {args.steps} (>= 1)")
    seeds = protocol_seeds(args)
    args.out.mkdir(parents=True, exist_ok=True)
    from benchmarks.results import record as write

    record = (lambda *a, **k: None) if args.no_record else write
    dataset = functools.cache(lambda: demonstrations(args.out, args.task))  # collected only if something is trained
    for name in args.variants:
        k = VARIANTS[name]["chunk_size"]
        executors = EXECUTORS[:1] if k == 1 else EXECUTORS
        per_seed: dict[str, dict[int, dict]] = {executor: {} for executor in executors}
        for ts in args.train_seeds:  # each run evaluated once trained: a cut sweep keeps what it finished
            load = functools.cache(lambda ts=ts: train_or_load(name, ts, args, dataset()))
            run = run_dir(args.out, name, ts, args.steps, args.task)
            for executor in executors:
                per_seed[executor][ts] = evaluate_run(load, run, executor, seeds, k, dataset, args.task)
        for executor in executors:
            summarise(name, executor, per_seed[executor], args, record)


if __name__ == "__main__":
    main()
