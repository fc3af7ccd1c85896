"""Real-time chunking in its regime (chapter 11, §10.4): the execution horizon s swept per delay d.

RTC (Black, Galliker and Levine 2025) is defined for d <= s <= H - d: s actions of a chunk are
executed before the next chunk's request (d of them while it is computed), and the soft guidance
region of the next chunk is what is left of the current one past those d frozen steps. Here H is
the usable horizon, the actions of a chunk from the current step on: H = Tp - To + 1 (15 for the
shipped PushT heads, Tp = 16, To = 2). ``bench_latency --only curves`` keeps each head's own Ta
(s = max(Ta, d)), where at d = 4 the soft weights are small and from d = 7 there is no soft region.

For each head, strategy (naive async, RTC) and d, every s of a grid inside the regime is scored on
VALIDATION seeds (200000+, ``--val-episodes``); the best s per (head, strategy, d) is then scored
on the 200 protocol seeds (100000-100199) with a bootstrap 95 % interval. s is never chosen on the
reported seeds. Rows, in the "Latency budget" section:

- "<head>, <strategy>, d=<d>, s=<s>: validation score" (n and seed range in the row),
- "<head>, <strategy>, d=<d>, best s: score" (the s chosen and the grid in the note), and its
  smoothness row;
- "<head>, d=<d>, best s: rtc minus async score" when both strategies ran: the paired difference
  per protocol seed, each strategy at its own best s (bootstrap 95 % interval).

Every point is evaluated in cached blocks (``bench_latency``'s cache), so an interrupted sweep
resumes where it stopped. For example (about an hour per head and strategy on one core)::

    .venv/bin/python -m benchmarks.bench_rtc_regime --heads dp,flow --strategies async,rtc --d 1,2,4,6
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from benchmarks.bench_latency import HEADS, SECTION, evaluate_blocks, load_head, mean_smoothness, missing_head, pusht_score
from benchmarks.protocol import PROTOCOL_START, VALIDATION_START
from benchmarks import results
from benchmarks.train_head import HEADS as TRAINED, command as train_command

COMMAND = ".venv/bin/python -m benchmarks.bench_rtc_regime"
STRATEGIES = ("async", "rtc")
"""The two strategies whose schedule s sets (synchronous and ensembling are not about s)."""


def regime_grid(d: int, horizon: int, points: int = 4, own: int | None = None) -> list[int]:
    """About ``points`` values of s spread evenly over RTC's regime d <= s <= H - d (plus ``own``,
    the head's own Ta, when it lies inside); empty when the regime is (d > H / 2)."""
    lo, hi = max(1, d), horizon - d
    if lo > hi:
        return []
    grid = {int(round(v)) for v in np.linspace(lo, hi, points)}
    if own is not None and lo <= own <= hi:
        grid.add(int(own))
    return sorted(grid)


def sweep_point(policy, name: str, strategy: str, d: int, args: argparse.Namespace) -> dict | None:
    """Validation sweep over s for one (head, strategy, d), then the chosen s on the protocol seeds.

    Returns {"s": the chosen s, "parts": its evaluated protocol blocks, "cmd"}, or None outside the regime."""
    record = (lambda *a, **k: None) if args.no_record else results.record
    label = HEADS[name][3]
    H = policy.execution_spec().usable_horizon
    own = policy.execution_spec().n_action_steps
    grid = regime_grid(d, H, args.points, own)
    if not grid:
        print(f"{label} d={d}: no s with d <= s <= H - d = {H - d}: skipped")
        return None
    val_seeds = list(range(VALIDATION_START, VALIDATION_START + args.val_episodes))
    cmd = (f"{COMMAND} --heads {name} --strategies {strategy} --d {d} --points {args.points} "
           f"--val-episodes {args.val_episodes} --episodes {args.episodes} --block {args.block}")
    trained = f"; head trained by: {train_command(name)}" if name in TRAINED else ""
    val = {}
    for s in grid:
        value, interval, n, span = pusht_score(evaluate_blocks(policy, name, strategy, d, val_seeds, args, s))
        val[s] = value
        record(SECTION, f"{label}, {strategy}, d={d}, s={s}: validation score", value, "", cmd, interval=interval,
               n=n, seeds=span, note=f"VALIDATION seeds (s is chosen here); usable horizon H = {H}, regime "
                                     f"{max(1, d)} <= s <= {H - d}; sampling seed {args.seed}{trained}")
    best = max(grid, key=lambda s: (val[s], -abs(s - own)))  # ties: the s closest to the head's own Ta
    parts = evaluate_blocks(policy, name, strategy, d, list(range(PROTOCOL_START, PROTOCOL_START + args.episodes)),
                            args, best)
    value, interval, n, span = pusht_score(parts)
    smooth = mean_smoothness(parts)
    chosen = ", ".join(f"s={s}: {val[s]:.3f}" for s in grid)
    note = (f"s = {best} chosen on {args.val_episodes} validation seeds ({chosen}); usable horizon H = {H}; "
            f"{n} held-out seeds{' (REDUCED run: the protocol is 200)' if n < 200 else ''}; sampling seed {args.seed}"
            + trained)
    record(SECTION, f"{label}, {strategy}, d={d}, best s: score", value, "", cmd, interval=interval, n=n,
           seeds=span, note=note)
    record(SECTION, f"{label}, {strategy}, d={d}, best s: smoothness",
           f"s = {best}: jump at switches {smooth['switch_jump']:.1f} px (other steps {smooth['other_step']:.1f}), "
           f"max jerk {smooth['max_jerk']:.1f} px/step^3", "", cmd, note=note + "; means over episodes", n=n, seeds=span)
    print(f"{label} {strategy} d={d}: best s = {best} of {grid} -> {value:.3f} [{interval[0]:.3f}, {interval[1]:.3f}]")
    return {"s": best, "parts": parts, "cmd": cmd}


def paired_difference(name: str, d: int, rtc: dict, naive: dict, no_record: bool) -> None:
    """RTC minus naive async, each at its own best s, paired by protocol seed (bootstrap 95 % interval)."""
    from coursekit.stats import mean_estimate

    def by_seed(point: dict) -> dict[int, float]:
        return {s: r for p in point["parts"] for s, r in zip(p["seeds"], p["max_reward"])}

    a, b = by_seed(rtc), by_seed(naive)
    seeds = sorted(set(a) & set(b))
    est = mean_estimate([a[s] - b[s] for s in seeds])
    label = HEADS[name][3]
    cmd = rtc["cmd"].replace("--strategies rtc", "--strategies rtc,async")
    note = (f"paired by protocol seed ({len(seeds)} seeds, same sampling seed); RTC at s = {rtc['s']}, naive async at "
            f"s = {naive['s']}, each chosen on validation seeds; bootstrap 95 % interval of the mean difference")
    print(f"{label} d={d}: rtc minus async {est.value:+.3f} [{est.lo:+.3f}, {est.hi:+.3f}]")
    if not no_record:
        results.record(SECTION, f"{label}, d={d}, best s: rtc minus async score", round(est.value, 3), "", cmd,
                       interval=(round(est.lo, 3), round(est.hi, 3)), n=est.n,
                       seeds=f"{seeds[0]}-{seeds[-1]}", note=note)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--heads", default="dp,flow", help=f"comma list of PushT heads of {list(HEADS)}")
    parser.add_argument("--strategies", default=",".join(STRATEGIES), help=f"comma list of {list(STRATEGIES)}")
    parser.add_argument("--d", default="1,2,4,6", help="comma list of delays d >= 1 in control steps")
    parser.add_argument("--points", type=int, default=4, help="values of s per regime (plus the head's own Ta)")
    parser.add_argument("--val-episodes", type=int, default=100, help="validation seeds per s (from 200000)")
    parser.add_argument("--episodes", type=int, default=200, help="protocol seeds for the chosen s (protocol: 200)")
    parser.add_argument("--block", type=int, default=50, help="seeds per cached block (the unit of resumption)")
    parser.add_argument("--seed", type=int, default=0, help="sampling seed (torch generator of every chunk's noise)")
    parser.add_argument("--max-guidance", type=float, default=5.0, help="RTC's guidance clip beta (paper: 5)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--no-record", action="store_true", help="print only (smoke runs): results.json untouched")
    parser.add_argument("--cache", default=os.path.join(os.environ.get("XDG_CACHE_HOME", "~/.cache"), "coursekit",
                                                        "bench_latency"), help="where evaluated blocks are kept")
    args = parser.parse_args(argv)
    args.prefix = "guide"
    heads = [h for h in args.heads.split(",") if h]
    strategies = [s for s in args.strategies.split(",") if s]
    delays = [int(x) for x in args.d.split(",") if x.strip()]
    bad = ([h for h in heads if h not in HEADS or HEADS[h][1] != "pusht"] + [s for s in strategies if s not in STRATEGIES]
           + [d for d in delays if d < 1])
    if bad or min(args.points, args.val_episodes, args.episodes, args.block, args.threads) < 1:
        raise SystemExit(f"bad value(s) {bad}: heads are PushT heads of {list(HEADS)}, strategies of {list(STRATEGIES)}, "
                         f"d >= 1; --points/--val-episodes/--episodes/--block/--threads >= 1")
    import torch

    torch.set_num_threads(args.threads)
    for name in heads:
        policy = load_head(name)
        if policy is None:
            print(missing_head(name))
            continue
        best = {}  # (strategy, d) -> sweep_point's result
        for strategy in strategies:
            if strategy == "rtc" and not hasattr(policy, "predict_inpainted"):
                continue  # RTC guides an iterative sampler: not ACT
            for d in delays:
                best[strategy, d] = sweep_point(policy, name, strategy, d, args)
        for d in delays:
            if best.get(("rtc", d)) and best.get(("async", d)):
                paired_difference(name, d, best["rtc", d], best["async", d], args.no_record)


if __name__ == "__main__":
    main()
