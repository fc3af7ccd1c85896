"""The course's PushT claims, measured on the shipped checkpoints: where multimodality bites.

    .venv/bin/python -m benchmarks.bench_claims --threads 1                 # 200 protocol seeds, DP DDIM-10 + regression
    .venv/bin/python -m benchmarks.bench_claims --policies dp_ddpm100 ...    # add the paper's sampler (~10x slower)
    .venv/bin/python -m benchmarks.bench_claims --episodes 4 --no-record     # smoke run

Parts (all resumable: per-episode results are saved under ``--out`` and reused when present):

- ``table``: for each reset seed, whether the clean expert's FIRST travel leg is a two-way coin
  toss (``coursekit.experts.pusht_two_ways.first_decision``), cached in
  ``benchmarks/two_way_starts.json`` (deterministic; recomputed only for missing seeds).
- ``eval``: the shipped DP (``dp_ddim10``; ``dp_ddpm100``) and the shipped chunked regression
  baseline (``regression``) on ``--episodes`` seeds from ``--seed-start`` (protocol: 100000+),
  300 steps, states recorded; per-episode files ``eval_<policy>_<first>_<n>.npz``.
- ``subsets``: score (bootstrap 95 % interval) and success (Wilson) on the two-way starts and on
  the rest, and the per-seed paired difference DP minus regression on each subset.
- ``hesitation``: steps per episode the pusher spends near-stalled against the block
  (``coursekit.evaluate.behaviour.stalled_steps``), per policy and subset.
- ``commitment``: from the first ``--commit-starts`` two-way starts, ``--commit-samples`` DP
  chunks each (DDIM-10, sampled at the reset observation): the share going clockwise,
  anticlockwise or round neither side (``path_side``), against the regression chunk's side.

ONE training seed per policy (the shipped checkpoints); ``bench_chunk_ablation`` retrains with
``--train-seeds``. Rows: section "Claims (PushT, shipped checkpoints)".
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.protocol import add_protocol_args, protocol_seeds

SECTION = "Claims (PushT, shipped checkpoints)"
ROOT = Path(__file__).resolve().parent.parent
TABLE = ROOT / "benchmarks" / "two_way_starts.json"
POLICIES = {"dp_ddim10": ("pusht_diffusion_state", {"sampler": "ddim", "num_inference_steps": 10}, "DP DDIM-10"),
            "dp_ddpm100": ("pusht_diffusion_state", {"sampler": "ddpm", "num_inference_steps": 100}, "DP DDPM-100"),
            "regression": ("pusht_regression_state", {}, "chunked regression")}
PARTS = ("table", "eval", "subsets", "hesitation", "commitment")
TRAINING = "one training seed (the shipped checkpoint)"
TRAINED = {"dp_ddim10": "DP trained 19259 steps (20 min on 2 threads + 40 min on 1)",
           "dp_ddpm100": "DP trained 19259 steps (20 min on 2 threads + 40 min on 1)",
           "regression": "8510 steps (31 min on 1 thread)"}
"""Training of the shipped checkpoints (their config.json "training"): the two are NOT step-matched."""


def seed_range(seeds: list[int]) -> str:
    return f"{seeds[0]}-{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) else ",".join(map(str, seeds))


def two_way_flags(seeds: list[int], write: bool = True) -> dict[int, dict]:
    """{seed: FirstDecision fields} from the cache, computing (and caching) missing seeds."""
    from dataclasses import asdict

    from coursekit.atomic import atomic_write_text
    from coursekit.experts.pusht_planner import EXPERT_VERSION
    from coursekit.experts.pusht_two_ways import two_way_table

    cache = json.loads(TABLE.read_text()) if TABLE.exists() else {"expert_version": EXPERT_VERSION, "seeds": {}}
    if cache.get("expert_version") != EXPERT_VERSION:
        raise ValueError(f"{TABLE} was made by expert version {cache.get('expert_version')!r}, not {EXPERT_VERSION!r}: "
                         f"move it aside and rerun")
    missing = [s for s in seeds if str(s) not in cache["seeds"]]
    if missing:
        print(f"running the expert on {len(missing)} seeds for the two-way table ...", flush=True)
        for d in two_way_table(missing):
            row = asdict(d)
            cache["seeds"][str(row.pop("seed"))] = row
        if write:
            cache["seeds"] = dict(sorted(cache["seeds"].items(), key=lambda kv: int(kv[0])))
            atomic_write_text(TABLE, json.dumps(cache, indent=0) + "\n")
    return {s: cache["seeds"][str(s)] for s in seeds}


def load_policy(name: str):
    from coursekit.checkpoint import find_checkpoint, load_checkpoint, read_checkpoint_info

    ckpt, sampling, _ = POLICIES[name]
    path = find_checkpoint(ckpt)
    if path is None:
        raise FileNotFoundError(f"no shipped checkpoint {ckpt!r}")
    return load_checkpoint(path, device="cpu"), sampling, read_checkpoint_info(path)["dataset"]


def evaluate_or_load(name: str, seeds: list[int], out: Path) -> dict[str, np.ndarray]:
    """Per-episode arrays (seeds, max_reward, success, length, states (N, T+1, 5) float32) of one policy."""
    from coursekit.atomic import atomic_path
    from coursekit.evaluate import evaluate_pusht

    path = out / f"eval_{name}_{seeds[0]}_{len(seeds)}.npz"
    if path.exists():
        data = dict(np.load(path))
        if data["seeds"].tolist() != seeds:
            raise ValueError(f"{path} holds seeds {seed_range(data['seeds'].tolist())}, not {seed_range(seeds)}")
        print(f"{name}: reusing {path}")
        return data
    policy, sampling, meta = load_policy(name)
    r = evaluate_pusht(policy, seeds=seeds, dataset_meta=meta, record=True, **sampling)
    data = {"seeds": np.asarray(seeds), "max_reward": r.max_reward, "success": r.success, "length": r.length,
            "states": r.states[..., :5].astype(np.float32), "seconds": np.asarray(r.seconds)}
    with atomic_path(path, suffix=".npz") as tmp:  # a killed evaluation leaves no half-written file
        np.savez_compressed(tmp, **data)
    print(f"{name}: score {r.score:.3f}, success {r.success_rate:.1%} on {len(seeds)} seeds, {r.seconds:.0f} s -> {path}")
    return data


def check_against(data: dict[str, np.ndarray], other: Path) -> str:
    """Compare with an earlier run's per-episode file (e.g. helper i14's DDIM-10 json); a note for the row."""
    if not other.exists():
        return ""
    ref = json.loads(other.read_text())
    common = [i for i, s in enumerate(data["seeds"].tolist()) if s in set(ref["seeds"])]
    idx = {s: i for i, s in enumerate(ref["seeds"])}
    same = sum(abs(data["max_reward"][i] - ref["max_reward"][idx[int(data["seeds"][i])]]) < 1e-9 for i in common)
    return f"; per-episode max reward identical to {other.name} on {same} of {len(common)} seeds"


def estimates(values: np.ndarray, success: np.ndarray | None = None):
    from coursekit.stats import mean_estimate, rate_estimate

    return mean_estimate(values), (rate_estimate(success.astype(bool)) if success is not None else None)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_protocol_args(parser)
    parser.add_argument("--policies", nargs="+", default=["dp_ddim10", "regression"], choices=sorted(POLICIES))
    parser.add_argument("--parts", nargs="+", default=list(PARTS), choices=PARTS)
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_claims", help="per-episode results")
    parser.add_argument("--commit-starts", type=int, default=16, help="two-way starts for the commitment part")
    parser.add_argument("--commit-samples", type=int, default=32, help="DP chunks sampled per start")
    parser.add_argument("--compare", type=Path, default=None, help="an earlier DDIM-10 per-episode json to check against")
    return parser.parse_args(argv)


def policy_rows(rec, name: str, data: dict, two: np.ndarray, seeds: list[int], parts: list[str]) -> None:
    """Score, success and (with "hesitation") stalling rows of one policy, on all, two-way and other starts."""
    label = POLICIES[name][2]
    subsets = {"all starts": np.ones_like(two), "two-way starts": two, "other starts": ~two}
    for subset, mask in subsets.items():
        where = seed_range(seeds) + ("" if subset == "all starts" else f" ({subset.split()[0]} subset)")
        if "subsets" in parts or "eval" in parts:
            score, success = estimates(data["max_reward"][mask], data["success"][mask])
            rec(f"{label} score, {subset}", score, "", f"mean of max reward; success {success}; {TRAINING}; "
                f"{TRAINED[name]}", where)
            rec(f"{label} success, {subset}", success, "", f"coverage > 0.95 within 300 steps; {TRAINING}; "
                f"{TRAINED[name]}", where)
        if "hesitation" in parts:
            from coursekit.evaluate.behaviour import stalled_steps, still_steps
            from coursekit.stats import rate_estimate

            stall = stalled_steps(data["states"][mask], data["length"][mask])
            rec(f"{label} steps stalled against the block, {subset}", estimates(stall.astype(float))[0], "steps",
                "per episode: pusher within 3 px of the T, moving < 2 px/step, T still (< 0.5 px, 0.005 rad); "
                f"mean of {np.mean(data['length'][mask]):.0f} steps per episode; {TRAINING}", where)
            rec(f"{label} episodes with >= 20 steps stalled against the block, {subset}",
                rate_estimate(stall >= 20), "", f"stalled as in the row above; {TRAINING}", where)
            early = still_steps(data["states"][mask], data["length"][mask], first=40)
            rec(f"{label} steps near-still in the first 40, {subset}", estimates(early.astype(float))[0], "steps",
                f"pusher moving < 2 px/step anywhere (dithering at the fork would show here); {TRAINING}", where)


def difference_rows(rec, results: dict[str, dict], two: np.ndarray, seeds: list[int]) -> None:
    """Each DP head minus the chunked regressor, paired per seed, on two-way and other starts."""
    if "regression" not in results:
        return
    for dp in [p for p in results if p.startswith("dp_")]:
        diff = results[dp]["max_reward"] - results["regression"]["max_reward"]
        for subset, mask in {"two-way starts": two, "other starts": ~two}.items():
            rec(f"{POLICIES[dp][2]} minus chunked regression, {subset}", estimates(diff[mask])[0], "",
                f"paired per seed, bootstrap over seeds; {TRAINING} each; NOT step-matched: "
                f"{TRAINED[dp]}, regression {TRAINED['regression']}",
                seed_range(seeds) + f" ({subset.split()[0]} subset)")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    seeds = protocol_seeds(args)
    args.out.mkdir(parents=True, exist_ok=True)
    flags = two_way_flags(seeds, write=not args.no_record)
    two = np.array([flags[s]["two_way"] for s in seeds])
    print(f"two-way first decision on {two.sum()} of {len(seeds)} seeds ({seed_range(seeds)})")
    cmd = (f".venv/bin/python -m benchmarks.bench_claims --episodes {args.episodes} --seed-start {args.seed_start} "
           f"--policies {' '.join(args.policies)} --commit-starts {args.commit_starts} "
           f"--commit-samples {args.commit_samples} --threads {args.threads}")

    def rec(name, est, unit, note, seeds_txt=seed_range(seeds)):
        print(f"  {name}: {est}")
        if not args.no_record:
            from benchmarks.results import record

            record(SECTION, name, est.value, unit, cmd, note=note, interval=(est.lo, est.hi), n=est.n,
                   seeds=seeds_txt)

    from coursekit.stats import rate_estimate

    if "table" in args.parts:
        rec("starts whose first expert decision is a two-way route choice", rate_estimate(two), "",
            "share of reset seeds; clean expert, first travel leg a coin toss between cw and ccw (within the route "
            "tolerance); cached in benchmarks/two_way_starts.json")
    if not {"eval", "subsets", "hesitation", "commitment"} & set(args.parts):
        return 0
    results = {name: evaluate_or_load(name, seeds, args.out) for name in args.policies}
    if args.compare is not None and "dp_ddim10" in results:
        print(check_against(results["dp_ddim10"], args.compare))
    for name, data in results.items():
        policy_rows(rec, name, data, two, seeds, args.parts)
    if "subsets" in args.parts:
        difference_rows(rec, results, two, seeds)
    if "commitment" in args.parts:
        from benchmarks.claims_commitment import commitment

        starts = [s for s in seeds if flags[s]["two_way"]][: args.commit_starts]
        expert_sides = [flags[s]["side"] for s in starts]
        for row in commitment(starts, args.commit_samples, load_policy, expert_sides):
            rec(row["name"], row["estimate"], "", row["note"],
                seeds_txt=f"first {len(starts)} two-way starts of {seed_range(seeds)} ({starts[0]}..{starts[-1]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
