"""PushT scripted expert: success, speed, multimodality and dataset generation time.

    .venv/bin/python -m benchmarks.bench_pusht_expert            # 200 protocol seeds + 200-episode dataset
    .venv/bin/python -m benchmarks.bench_pusht_expert --collect 0  # the protocol seeds only
    .venv/bin/python -m benchmarks.bench_pusht_expert --no-record  # print only

Measures, on the resets ``env.reset(seed=s)`` for s in [first_seed, first_seed + seeds) (default
100000-100199, the protocol's held-out range, so the expert is judged where the policies are):
success rate (coverage > 0.95 within 300 steps; Wilson 95 % interval), mean (bootstrap 95 %
interval) / p90 / max steps to success, the
fraction of episodes with a real two-way route choice (a coin toss between clockwise and
anticlockwise), the split of those choices (first toss of each episode, side taken), the
largest distance between consecutive targets, travel legs that touched the block; and the
wall time of ``collect_dataset(200, seed=0)``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from coursekit.stats import mean_estimate, rate_estimate

SECTION = "PushT expert"


def measure(n_seeds: int, first_seed: int = 0) -> dict[str, float | np.ndarray]:
    """Run the expert on seeds first_seed .. first_seed + n_seeds - 1 and summarise."""
    from coursekit.envs.pusht import PushTEnv
    from coursekit.experts.pusht_planner import TRAVEL, PushTExpert

    expert, env = PushTExpert(), PushTEnv(obs_type="state")
    steps, first_sides, n_choice, bumps, max_jump, travel_moves = [], [], 0, 0, 0.0, 0.0
    for seed in range(first_seed, first_seed + n_seeds):
        rec = expert.run_episode(env, seed)
        steps.append(rec.success_step if rec.success_step is not None else np.inf)
        if rec.route_choices:
            n_choice += 1
            first_sides.append(rec.route_choices[0]["taken"])
        bumps += rec.travel_bumps
        max_jump = max(max_jump, float(np.linalg.norm(np.diff(rec.actions, axis=0), axis=1).max()))
        travel = np.flatnonzero(rec.phases[:-1] == TRAVEL)  # block pose change over travel steps
        if len(travel):
            moved = np.abs(rec.states[travel + 1, 2:5] - rec.states[travel, 2:5]).max()
            travel_moves = max(travel_moves, float(moved))
    steps = np.asarray(steps, dtype=float)
    ok = np.isfinite(steps)
    cw = first_sides.count("cw")
    return {
        "ok": ok, "steps": steps, "first_sides": np.asarray(first_sides),
        "success": float(ok.mean()), "mean_steps": float(steps[ok].mean()),
        "p90_steps": float(np.percentile(np.where(ok, steps, 1e9), 90)), "max_steps": float(steps[ok].max()),
        "choice_fraction": n_choice / n_seeds, "cw_share": cw / max(len(first_sides), 1),
        "n_choices": float(len(first_sides)), "travel_bumps": float(bumps), "max_target_jump": max_jump,
        "max_travel_block_move": travel_moves,
    }


def time_collect(n_episodes: int) -> tuple[float, float, dict]:
    """(wall seconds, CPU seconds of this process, dataset meta) of collect_dataset(n, seed=0)."""
    from coursekit.experts.pusht_planner import collect_dataset

    start, cpu = time.perf_counter(), time.process_time()
    dataset = collect_dataset(n_episodes, seed=0, progress=False)
    return time.perf_counter() - start, time.process_time() - cpu, dataset.meta


COMMAND = ".venv/bin/python -m benchmarks.bench_pusht_expert"


def record_seed_rows(r: dict, n: int, first_seed: int, record) -> None:
    """The expert's figures on seeds first_seed..first_seed + n - 1: rates with Wilson intervals, the
    mean step count with a bootstrap one (over the successful episodes), every row with n and seeds."""
    span, cmd = f"{first_seed}-{first_seed + n - 1}", f"{COMMAND} --seeds {n} --first-seed {first_seed}"
    success = rate_estimate(r["ok"])
    record(SECTION, "success rate", round(100 * success.value, 1), "%", cmd, target=">= 98 %",
           note=f"coverage > 0.95 within 300 steps, resets seed {span}; Wilson 95 % interval",
           interval=(round(100 * success.lo, 1), round(100 * success.hi, 1)), n=n, seeds=span)
    if r["ok"].any():
        steps = mean_estimate(r["steps"][r["ok"]])
        record(SECTION, "steps to success (mean)", round(steps.value, 2), "steps", cmd, target="<= 110",
               note=f"over the {steps.n} successful episodes, bootstrap 95 % interval; p90 {r['p90_steps']:.0f}, "
                    f"max {r['max_steps']:.0f}", interval=(round(steps.lo, 2), round(steps.hi, 2)), n=steps.n, seeds=span)
    record(SECTION, "steps to success (p90)", r["p90_steps"], "steps", cmd, n=n, seeds=span,
           note="90th percentile over all episodes (a failure counts as never)")
    choice = rate_estimate(np.asarray([True] * int(r["n_choices"]) + [False] * (n - int(r["n_choices"]))))
    record(SECTION, "episodes with a two-way route choice", round(100 * choice.value, 1), "%", cmd, target=">= 30 %",
           note="clockwise and anticlockwise within the route tolerance: a seeded coin picks; Wilson 95 % interval",
           interval=(round(100 * choice.lo, 1), round(100 * choice.hi, 1)), n=n, seeds=span)
    if len(r["first_sides"]):
        cw = rate_estimate(r["first_sides"] == "cw")
        record(SECTION, "clockwise share of choices", round(100 * cw.value, 1), "%", cmd, target="40-60 %",
               note=f"first choice of each of {cw.n} episodes, side taken; Wilson 95 % interval",
               interval=(round(100 * cw.lo, 1), round(100 * cw.hi, 1)), n=cw.n, seeds=span)
    record(SECTION, "largest step between targets", r["max_target_jump"], "px", cmd, target="<= 40 px", n=n, seeds=span)
    record(SECTION, "travel legs touching the block", r["travel_bumps"], "legs", cmd, target="0", n=n, seeds=span,
           note=f"largest block move during travel {r['max_travel_block_move']:.2g} px (settling out of a wall)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=200, help="number of resets (protocol: 200)")
    parser.add_argument("--first-seed", type=int, default=100_000,
                        help="first reset seed (protocol: 100000; demonstrations use 0..)")
    parser.add_argument("--collect", type=int, default=200, help="episodes in the timed dataset (0: skip)")
    parser.add_argument("--no-record", action="store_true", help="print, do not write results.json")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.first_seed < 0 or args.collect < 0:
        parser.error(f"need --seeds >= 1, --first-seed >= 0, --collect >= 0; got {args.seeds}, {args.first_seed}, "
                     f"{args.collect}")
    r = measure(args.seeds, args.first_seed)
    seconds, cpu, meta = time_collect(args.collect) if args.collect else (float("nan"), float("nan"), {})
    load = os.getloadavg()[0]
    firsts = [ep[0]["taken"] for ep in meta.get("route_choices", []) if ep]
    print(f"success {r['success']:.1%} | steps mean {r['mean_steps']:.1f} p90 {r['p90_steps']:.0f} "
          f"max {r['max_steps']:.0f} | two-way choice {r['choice_fraction']:.0%} of episodes, "
          f"clockwise {r['cw_share']:.0%} of {r['n_choices']:.0f} | travel bumps {r['travel_bumps']:.0f}, "
          f"block moved during travel {r['max_travel_block_move']:.2g} | largest target step "
          f"{r['max_target_jump']:.1f} px | collect {args.collect}: {seconds:.1f} s wall, {cpu:.1f} s CPU "
          f"(load average {load:.1f}); dataset: two-way choice in {len(firsts)} episodes, "
          f"clockwise {firsts.count('cw')}")
    if args.no_record:
        return 0
    from benchmarks.results import record

    record_seed_rows(r, args.seeds, args.first_seed, record)
    if args.collect:
        cmd = f"{COMMAND} --collect {args.collect}"
        record(SECTION, f"collect {args.collect} demonstrations", seconds, "s", cmd, target="< 60 s on 2 cores",
               note=f"collect_dataset({args.collect}, seed=0), state observations, one process: {cpu:.1f} s CPU, "
                    f"load average {load:.1f} while measured")
        record(SECTION, f"two-way choices in the {args.collect}-episode dataset", len(firsts) / args.collect * 100,
               "%", cmd, target=">= 30 %, split 40/60..60/40",
               note=f"clockwise {firsts.count('cw')} of {len(firsts)}")
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
