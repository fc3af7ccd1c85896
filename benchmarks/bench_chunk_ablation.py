"""The chunk ablation the course argues from: is it the chunk or the generator?

    # DP score vs Ta on the SHIPPED checkpoint (Ta is an execution choice: no retraining)
    .venv/bin/python -m benchmarks.bench_chunk_ablation --only ta --episodes 200 --threads 1
    # the heads, same data and step budget, three training seeds each (one run per core, resumable)
    .venv/bin/python -m benchmarks.bench_chunk_ablation --only train --steps 6000 --train-seeds 0 1 2 --threads 1
    .venv/bin/python -m benchmarks.bench_chunk_ablation --only train --steps 20 --episodes 2 --no-record  # smoke

Parts:

- ``ta``: the shipped DP (``coursekit/checkpoints/pusht_diffusion_state``, To = 2, Tp = 16, one
  training seed) with DDIM-10 at Ta in ``--ta`` (default 1, 2, 4, 8, 15: Ta = 16 does not fit,
  the executed slice pred[To-1 : To-1+Ta] needs To - 1 + Ta <= Tp) on ``--episodes`` seeds from
  ``--seed-start``: small Ta re-plans often (reactive, but may switch modes between chunks), large
  Ta executes longer open-loop stretches (compounding error); Chi et al. 2023, Sec. 3.1 / Fig. 6.
- ``train``: the variants of :data:`VARIANTS` (single-step regression, chunked regression, ACT,
  DP) on the same demonstrations (``--data``, default the shipped models' 400 DART 0/5 episodes)
  and features (``pusht_keypoints``), the same step budget (``--steps``, the "cpu"
  recipe, one thread), each with every seed of ``--train-seeds``; evaluated on the same seeds.
  A row per variant: the mean score over training seeds, a t-interval over training seeds
  (95 %; with 3 seeds it is wide on purpose), and the per-seed scores in the note. The same
  split by start (``benchmarks/two_way_starts.json``: is the expert's first decision a two-way
  coin toss?) gives each variant's score on the two-way and the other starts, and Diffusion
  Policy's lead over each regression variant on both subsets, paired by training seed (the
  chapter-1 question: is the gap larger where the demonstrations split?).

Per-episode results go under ``--out``, a cache outside the repository: an existing run or
evaluation is reused, and a killed training run resumes where it stopped (``benchmarks.resumable``).
An evaluation kept in the repository's ledger (``python -m benchmarks.ledger``) is read from there,
and its run is then neither trained nor loaded.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.protocol import add_protocol_args, protocol_seeds, t_estimate
from benchmarks.resumable import cache_dir, evaluation_file, run_slug
from coursekit.atomic import atomic_write_text

SECTION = "Chunk ablation (PushT)"
ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "outputs" / "data" / "pusht_400ep_seed0_noise0-5.npz"
"""What ``coursekit collect pusht --episodes 400 --seed 0 --action-noise 0,5`` writes: the shipped models' data."""
CACHE = cache_dir("chunk_ablation")
"""Where the trained runs and their evaluations live (outside the repository; resumable)."""
VARIANTS = {
    "single-step regression (To=1, Tp=Ta=1)": ("regression", {"n_obs_steps": 1, "horizon": 1, "n_action_steps": 1,
                                                               "unet": {"down_dims": (256,)}}, {}),
    "chunked regression (To=2, Tp=16, Ta=8)": ("regression", {}, {}),
    "ACT (k=16, temporal ensembling)": ("act", {"chunk_size": 16}, {}),
    "Diffusion Policy DDIM-10 (To=2, Tp=16, Ta=8)": ("diffusion", {}, {"sampler": "ddim", "num_inference_steps": 10}),
}
"""name -> (policy type, config fields, sampling). Single-step needs a one-level U-Net (Tp = 1 cannot be halved)."""
SHIPPED = {"diffusion": ("pusht_diffusion_state", "shipped DP DDIM-10", "dp_ddim10", {"sampler": "ddim", "num_inference_steps": 10}),
           "regression": ("pusht_regression_state", "shipped chunked regression", "regression", {})}
"""--policy of part ta -> (checkpoint, row label, bench_claims file tag, sampling)."""


def seed_text(seeds: list[int]) -> str:
    return f"{seeds[0]}-{seeds[-1]}"


def evaluate_saved(load, path: Path, seeds: list[int], meta: dict | None, sampling: dict) -> dict:
    """Reuse ``path``, or evaluate ``load()`` (called only then) into it: {"seeds", "max_reward", "success"} lists."""
    from coursekit.evaluate import evaluate_pusht

    if path.exists():
        saved = json.loads(path.read_text())
        if saved["seeds"] != seeds:
            raise ValueError(f"{path} holds other seeds ({seed_text(saved['seeds'])}); move it aside")
        return saved
    policy = load()
    r = evaluate_pusht(policy, seeds=seeds, dataset_meta=meta, progress=False, **sampling)
    saved = {"seeds": seeds, "max_reward": r.max_reward.tolist(), "success": r.success.tolist(), "seconds": r.seconds,
             "n_action_steps": policy.config.n_action_steps, **{k: v for k, v in sampling.items()}}
    atomic_write_text(path, json.dumps(saved) + "\n")  # a killed evaluation leaves no half-written file
    return saved


def part_ta(args, seeds: list[int], rec) -> None:
    from coursekit.checkpoint import find_checkpoint, load_checkpoint, read_checkpoint_info
    from coursekit.stats import mean_estimate, rate_estimate

    ckpt, label, tag, sampling = SHIPPED[args.policy]
    prefix = "" if args.policy == "diffusion" else f"{args.policy}_"
    path = find_checkpoint(ckpt)
    dp, meta = load_checkpoint(path, device="cpu"), read_checkpoint_info(path)["dataset"]
    for ta in args.ta:
        policy = dp.with_config(n_action_steps=int(ta))  # validated copy: To - 1 + Ta <= Tp
        claims = ROOT / "outputs" / "bench_claims" / f"eval_{tag}_{seeds[0]}_{len(seeds)}.npz"
        if ta == dp.config.n_action_steps and claims.exists():  # the same evaluation, made by bench_claims
            data = np.load(claims)
            if data["seeds"].tolist() == seeds:
                out = args.out / f"{prefix}ta{ta}_{seeds[0]}_{len(seeds)}.json"
                atomic_write_text(out, json.dumps({"seeds": seeds, "max_reward": data["max_reward"].tolist(),
                                           "success": data["success"].tolist(), "seconds": float(data["seconds"]),
                                           "from": str(claims.relative_to(ROOT))}) + "\n")
        saved = evaluate_saved(lambda: policy, args.out / f"{prefix}ta{ta}_{seeds[0]}_{len(seeds)}.json", seeds, meta, sampling)
        score, ok = mean_estimate(saved["max_reward"]), rate_estimate(np.asarray(saved["success"], dtype=bool))
        rec(f"{label} score, Ta={ta}", score,
            f"success {ok}; To={policy.config.n_obs_steps}, Tp={policy.config.horizon}; shipped checkpoint, one "
            f"training seed; {saved['seconds']:.0f} s to evaluate")


def run_dir(out: Path, name: str, ts: int, steps: int, data: Path) -> Path:
    """The cache folder of variant ``name``, training seed ``ts``, ``steps`` on the demonstrations ``data``.

    Runs on the shipped models' demonstrations (a file named like :data:`DATA`) keep the plain name;
    runs on any other data set carry its file stem, so two data sets never share a run."""
    tag = "" if data.name == DATA.name else f"_{data.stem}"
    return out / f"{run_slug(name)}_seed{ts}_s{steps}{tag}"


def train_or_load(name: str, ts: int, args, dataset):
    """The variant ``name`` trained with training seed ``ts`` (or loaded from ``--out``)."""
    from benchmarks.resumable import load_or_train
    from coursekit.nn.unet1d import UNet1DConfig
    from coursekit.policies import make_policy

    kind, fields, _ = VARIANTS[name]
    cfg = dict(fields)
    if "unet" in cfg:
        cfg["unet"] = UNet1DConfig(**cfg["unet"])
    run = run_dir(args.out, name, ts, args.steps, args.data)
    build = lambda: make_policy(kind, dataset, features="pusht_keypoints", recipe="cpu", seed=ts, **cfg)  # noqa: E731
    return load_or_train(run, build, args.steps, ts, args.threads, dataset.meta)


def data_label(meta: dict) -> str:
    """What the row names add for the demonstrations: nothing for the scripted planner's, else their style."""
    style = meta.get("expert_style")
    return "" if not style else ", person-like demonstrations"


def part_train(args, seeds: list[int], rec) -> None:
    from benchmarks.bench_claims import two_way_flags
    from coursekit.data.episodes import EpisodeDataset

    dataset = EpisodeDataset.load(args.data)
    flags = two_way_flags(seeds, write=False)
    two = np.array([flags[s]["two_way"] for s in seeds])  # (n,) bool
    subsets = {"all starts": np.ones_like(two), "two-way starts": two, "other starts": ~two}
    conditions = (f"{args.data.name}, pusht_keypoints, recipe cpu, budget "
                  f"{args.steps} steps, {args.threads} thread(s)")
    budget = f", {args.steps} steps" if args.name_budget else ""  # the budget curve's rows
    budget += data_label(dataset.meta)  # rows on other demonstrations are other rows
    rewards: dict[str, np.ndarray] = {}  # variant -> (training seeds, n) max reward
    for name, (_, _, sampling) in VARIANTS.items():
        if args.variants and not any(v in name for v in args.variants):
            continue
        per_seed = []
        for ts in args.train_seeds:
            run = run_dir(args.out, name, ts, args.steps, args.data)  # trained only if its evaluation is not kept
            saved = evaluate_saved(lambda ts=ts: train_or_load(name, ts, args, dataset),
                                   evaluation_file(run, f"eval_{seeds[0]}_{len(seeds)}.json"), seeds, dataset.meta, sampling)
            per_seed.append(np.asarray(saved["max_reward"], dtype=float))
            print(f"{name}, training seed {ts}: score {per_seed[-1].mean():.3f} "
                  f"(two-way {per_seed[-1][two].mean():.3f}, other {per_seed[-1][~two].mean():.3f})", flush=True)
        rewards[name] = np.stack(per_seed)  # (k, n)
        k = len(per_seed)
        for subset, mask in subsets.items():
            scores = [float(r[mask].mean()) for r in per_seed]
            mean, lo, hi = t_estimate(scores)
            label = f"{name} score, {k} training seed(s){budget}" + ("" if subset == "all starts" else f", {subset}")
            rec(label, (mean, max(0.0, lo), min(1.0, hi), k * int(mask.sum())),
                f"mean over training seeds {args.train_seeds} (per seed: {', '.join(f'{s:.3f}' for s in scores)}; "
                f"sd {np.std(scores, ddof=1) if k > 1 else 0.0:.3f}); 95 % t-interval over training seeds; "
                f"{int(mask.sum())} starts per seed; {conditions}")
    dp = next((n for n in rewards if n.startswith("Diffusion Policy")), None)
    for other in [n for n in rewards if "regression" in n and dp is not None]:
        short = other.split(" (")[0]
        for subset, mask in subsets.items():
            gaps = [float(a[mask].mean() - b[mask].mean()) for a, b in zip(rewards[dp], rewards[other])]
            mean, lo, hi = t_estimate(gaps)
            rec(f"DP DDIM-10 minus {short}, {len(gaps)} training seed(s){budget}, {subset}",
                (mean, lo, hi, len(gaps) * int(mask.sum())),
                f"paired by training seed {args.train_seeds} (same seed for both; per seed: "
                f"{', '.join(f'{g:+.3f}' for g in gaps)}); 95 % t-interval over training seeds; "
                f"{int(mask.sum())} starts per seed; step-matched, {conditions}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("ta", "train"), default="ta", help="ta: the shipped DP vs Ta; train: the multi-seed ablation")
    add_protocol_args(parser)
    parser.add_argument("--policy", choices=sorted(SHIPPED), default="diffusion", help="shipped checkpoint (part ta)")
    parser.add_argument("--ta", type=int, nargs="+", default=[15, 8, 4, 2, 1], help="Ta values (part ta)")
    parser.add_argument("--train-seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--variants", nargs="+", default=[], help="substrings of variant names to run (default all)")
    parser.add_argument("--steps", type=int, default=6000,
                        help="training budget per run in optimiser steps (a step budget: sharing a core cannot change it)")
    parser.add_argument("--name-budget", action="store_true",
                        help="put the step budget in the row names (the budget curve: one set of rows per --steps)")
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--out", type=Path, default=CACHE, help=f"trained runs and evaluations (default {CACHE})")
    args = parser.parse_args(argv)
    seeds = protocol_seeds(args)
    if args.only == "train" and not args.data.exists():
        raise SystemExit(f"--data {args.data} does not exist (make it with: coursekit collect pusht --episodes 400 "
                         f"--action-noise 0,5)")
    args.out.mkdir(parents=True, exist_ok=True)
    cmd = f".venv/bin/python -m benchmarks.bench_chunk_ablation --only {args.only} --episodes {args.episodes} " \
          f"--seed-start {args.seed_start} --threads {args.threads}" + (f" --policy {args.policy}" if args.only == "ta" else "")
    if args.only == "train":
        cmd += f" --train-seeds {' '.join(map(str, args.train_seeds))} --steps {args.steps}"
        cmd += "".join(f" --variants '{v}'" if i == 0 else f" '{v}'" for i, v in enumerate(args.variants))
        cmd += " --name-budget" if args.name_budget else ""
        if args.data.name != DATA.name:  # the planner's data are the default; other demonstrations are named
            home = str(Path.home())
            data = str(args.data.resolve())
            cmd += f" --data {'~' + data[len(home):] if data.startswith(home + '/') else data}"

    def rec(name, est, note):
        value, lo, hi, n = (est.value, est.lo, est.hi, est.n) if hasattr(est, "value") else est
        print(f"  {name}: {value:.3f} [{lo:.3f}, {hi:.3f}] (n={n}); {note}", flush=True)
        if not args.no_record:
            from benchmarks.results import record

            record(SECTION, name, value, "", cmd, note=note, interval=(lo, hi), n=n, seeds=seed_text(seeds))

    (part_ta if args.only == "ta" else part_train)(args, seeds, rec)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
