"""The latency budget (chapter 11, §10.4): chunk latency -> delay d, and score vs d for each strategy.

Parts (``--only``; default: both):

- ``latency``: median ms per chunk (batch 1, this CPU) of every head and sampler, the d it means
  at each control rate (PushT 10 Hz, arm pair 50 Hz), and ms per action with the head's own executor;
  RTC's guided sampler is timed too (it adds a backward pass per step).
- ``curves``: the score of each (head, strategy, d) on held-out seeds with
  :func:`coursekit.evaluate.evaluate` and the strategy's executor (``coursekit.execution.rtc.STRATEGIES``),
  plus the smoothness of the executed actions (:func:`coursekit.evaluate.smoothness`: mean jump at
  chunk switches, largest jerk). PushT: mean of max coverage with a bootstrap 95 %
  interval; transfer cube: strict success with a Wilson interval.

The protocol is 200 held-out seeds (100000-100199) per point for d in {0, 1, 2, 4, 8}. Every point
is evaluated in blocks of ``--block`` seeds cached as JSON under ``--cache`` (never in the
repository), so an interrupted or partial run resumes where it stopped; a row is recorded only
for the seeds actually evaluated, with n and the seed range in the row. Run a subset with
``--heads``, ``--strategies``, ``--d``, ``--episodes`` and ``--seed-start``, e.g.::

    .venv/bin/python -m benchmarks.bench_latency --only curves --heads dp --strategies async,rtc --d 0,4 --episodes 20

Heads: dp (shipped PushT DP, its DDIM-10), dp-ddpm (the same with DDPM-100), flow (the shipped
PushT flow policy, Euler-10, if present), act (ACT on PushT), act-cube (ACT, transfer cube),
dp-cube (DP, transfer cube), flow-tp32 (a flow head with a longer horizon, Tp = 32, trained like the
shipped one: not shipped; trained by ``benchmarks/train_head.py`` into its ``TRAINED_HEADS``),
dp-pixels (chapter 12's pixel policy: two 96x96 frames + the pusher position; until its checkpoint
exists the latency part times its architecture with fresh weights).
RTC needs a diffusion or flow head and is skipped for ACT.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from benchmarks.results import record
from benchmarks.train_head import HEADS as TRAINED, TRAINED_HEADS, command as train_command
from coursekit.atomic import atomic_write_text
from coursekit.execution.rtc import STRATEGIES

ROOT = Path(__file__).resolve().parent.parent
CKPT = ROOT / "coursekit" / "checkpoints"
COMMAND = ".venv/bin/python -m benchmarks.bench_latency"
SECTION = "Latency budget"
HEADS = {  # name -> (checkpoint dir, task, sampling options, label)
    "dp": ("pusht_diffusion_state", "pusht", {}, "PushT DP DDIM-10"),
    "dp-ddpm": ("pusht_diffusion_state", "pusht", {"sampler": "ddpm", "num_inference_steps": 100}, "PushT DP DDPM-100"),
    "flow": ("pusht_flow_state", "pusht", {}, "PushT flow Euler-10"),
    "act": ("act_pusht", "pusht", {}, "PushT ACT"),
    "act-cube": ("act_transfer_cube", "transfer_cube", {}, "transfer cube ACT"),
    "dp-cube": ("dp_transfer_cube", "transfer_cube", {}, "transfer cube DP DDIM-10"),
    "flow-tp32": ("pusht_flow_state_tp32", "pusht", {}, "PushT flow Euler-10 (Tp = 32)"),
    "dp-pixels": ("pusht_diffusion_pixels", "pusht", {}, "PushT pixel DP DDIM-10 (two 96x96 frames at 48x48)"),
}
DELAYS = (0, 1, 2, 4, 8)
STRATEGY_NAMES = tuple(STRATEGIES)  # sync, async, ensemble, rtc


def _csv(text: str, allowed: tuple | None, kind: type = str) -> list:
    items = [kind(x) for x in text.split(",") if x.strip()]
    if allowed is not None:
        bad = [x for x in items if x not in allowed]
        if bad:
            raise SystemExit(f"unknown value(s) {bad}; expected some of {list(allowed)}")
    return items


def missing_head(name: str) -> str:
    """Why the head ``name`` is skipped, and how to make it when it is not shipped."""
    where = f"{CKPT / HEADS[name][0]}" + (f" nor {TRAINED_HEADS / HEADS[name][0]}" if name in TRAINED else "")
    how = f" (train it: {train_command(name)})" if name in TRAINED else ""
    return f"{name}: no checkpoint {where}{how}, skipped"


def load_head(name: str):
    from coursekit.checkpoint import load_checkpoint

    path = CKPT / HEADS[name][0]
    if not path.is_dir():
        path = TRAINED_HEADS / HEADS[name][0]
    if not path.is_dir():
        return None
    return load_checkpoint(path, device="cpu")


def pixel_architecture():
    """benchmarks/bench_pixel_policy's image DP (its "small" encoder, the default U-Net) with fresh weights."""
    import torch

    from benchmarks.bench_pixel_policy import encoder_config
    from coursekit.data import MinMaxNormalizer
    from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig

    torch.manual_seed(0)
    policy = DiffusionPolicy(DiffusionPolicyConfig(obs_type="image", features="pusht_image", obs_dim=2,
                                                   vision=encoder_config()))
    arena = MinMaxNormalizer(np.zeros(2), np.full(2, 512.0))  # PushT's 512 px arena, for agent_pos and targets
    policy.set_normalizers({"agent_pos": arena, "action": arena})
    return policy


UNTRAINED_FOR_LATENCY = {"dp-pixels": pixel_architecture}
"""Head -> its architecture with fresh weights, which the latency part times until a checkpoint exists:
how long a chunk takes does not depend on the weights (chapter 12's pixel policy, not shipped yet)."""


def part_latency(args: argparse.Namespace) -> None:
    from coursekit.evaluate.latency import chunk_latency_ms, latency_delay

    for name in args.heads:
        policy, weights = load_head(name), ""
        if policy is None and name in UNTRAINED_FOR_LATENCY:
            policy, weights = UNTRAINED_FOR_LATENCY[name](), "its architecture with fresh weights (no checkpoint yet: the time per chunk does not depend on the weights); "
        if policy is None:
            print(missing_head(name))
            continue
        _, task, sampling, label = HEADS[name]
        ms = chunk_latency_ms(policy, task, sampling=sampling, repeats=args.repeats)
        spec = policy.execution_spec()
        per_action = ms / (1 if spec.temporal_ensembling else spec.n_action_steps)
        d10, d50 = latency_delay(ms, "pusht"), latency_delay(ms, "transfer_cube")
        note = (f"{weights}batch 1, median of {args.repeats} after a warm-up, torch threads {_threads()}, 1-min load "
                f"average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; d = ceil(latency x rate): "
                f"{d10} at 10 Hz (PushT), {d50} at 50 Hz (arm pair)")
        print(f"{label}: {ms:.1f} ms per chunk, {per_action:.2f} ms per action, d = {d10} at 10 Hz, {d50} at 50 Hz")
        cmd = f"{COMMAND} --only latency --heads {name} --repeats {args.repeats} --threads {args.threads}"
        rows = [(f"{label}: ms per chunk", round(ms, 1), note), (f"{label}: ms per action (own executor)",
                                                                round(per_action, 2), note)]
        if hasattr(policy, "predict_inpainted"):  # an iterative sampler RTC can guide
            g = chunk_latency_ms(policy, task, sampling=sampling, repeats=args.repeats, guided=True)
            print(f"{label} RTC-guided: {g:.1f} ms per chunk ({g / ms:.1f}x)")
            rows.append((f"{label}: ms per RTC-guided chunk", round(g, 1),
                         f"guidance adds a backward pass per step ({g / ms:.1f}x the plain chunk); " + note))
        for row, value, row_note in ([] if args.no_record else rows):
            record(SECTION, row, value, "ms", cmd, note=row_note)


def _threads() -> int:
    import torch

    return torch.get_num_threads()


def _block_file(cache: Path, name: str, strategy: str, d: int, start: int, n: int, args: argparse.Namespace,
                s: int | None = None) -> Path:
    rtc = f"_beta{args.max_guidance:g}_{args.prefix}" if strategy == "rtc" else ""
    horizon = "" if s is None else f"_exec{s}"  # s: actions executed per chunk, when not the head's own Ta
    tag = f"{name}_{strategy}_d{d}_s{start}_n{n}_seed{args.seed}{rtc}{horizon}"
    return cache / f"{tag}.json"


def evaluate_blocks(policy, name: str, strategy: str, d: int, seeds: list[int], args: argparse.Namespace,
                    s: int | None = None) -> list[dict]:
    """Evaluate ``seeds`` in cached blocks of ``args.block`` (resumable); with ``s``, the head executes s per chunk."""
    run = policy if s is None else policy.with_config(n_action_steps=s)
    cache = Path(args.cache).expanduser()
    cache.mkdir(parents=True, exist_ok=True)
    parts = []
    for b in (seeds[i:i + args.block] for i in range(0, len(seeds), args.block)):
        f = _block_file(cache, name, strategy, d, b[0], len(b), args, s)
        if f.is_file():
            parts.append(json.loads(f.read_text()))
            continue
        part = run_block(run, name, strategy, d, b, args)
        atomic_write_text(f, json.dumps(part))  # a killed run leaves no half-written block
        parts.append(part)
        print(f"  {HEADS[name][3]} {strategy} d={d}{'' if s is None else f' s={s}'} seeds {b[0]}..{b[-1]}: "
              f"{np.mean(part['max_reward']):.3f} ({part['seconds']:.0f} s)", flush=True)
    return parts


def pusht_score(parts: list[dict]) -> tuple[float, tuple[float, float], int, str]:
    """Mean max coverage of evaluated blocks, its bootstrap 95 % interval (rounded to 3 places and
    widened to contain the rounded mean), n and the seed span "first-last"."""
    from coursekit.stats import bootstrap_interval

    scores = np.array([x for p in parts for x in p["max_reward"]])  # (n,) max coverage per episode
    seeds = [s for p in parts for s in p["seeds"]]
    lo, hi = bootstrap_interval(scores) if len(scores) > 1 else (scores[0], scores[0])
    value = round(float(scores.mean()), 3)
    return value, (min(round(lo, 3), value), max(round(hi, 3), value)), len(seeds), f"{min(seeds)}-{max(seeds)}"


def mean_smoothness(parts: list[dict]) -> dict[str, float]:
    """Each smoothness figure of evaluated blocks, averaged over episodes (blocks weighted by their seeds)."""
    return {k: float(np.average([p["smooth"][k] for p in parts], weights=[len(p["seeds"]) for p in parts]))
            for k in parts[0]["smooth"]}


def run_block(policy, name: str, strategy: str, d: int, seeds: list[int], args: argparse.Namespace) -> dict:
    from coursekit.evaluate import evaluate, make_adapter, smoothness

    _, task, sampling, _ = HEADS[name]
    options = {"delay": d, **({"max_guidance": args.max_guidance, "prefix": args.prefix} if strategy == "rtc" else {})}
    r = evaluate(policy, make_adapter(task, policy), seeds, seed=args.seed, sampling=sampling, record=True,
                 executor_cls=STRATEGIES[strategy], executor_options=options, progress=False)
    out = {"seeds": seeds, "max_reward": r.max_reward.tolist(), "success": r.success.astype(int).tolist(),
           "smooth": smoothness(r.actions, r.info["switches"]), "seconds": r.seconds}
    if task != "pusht":
        out["strict"] = (r.states[:, -1, 1] > 0.5).astype(int).tolist()
    return out


def part_curves(args: argparse.Namespace) -> None:
    from coursekit.stats import wilson_interval

    seeds_all = list(range(args.seed_start, args.seed_start + args.episodes))
    for name in args.heads:
        policy = load_head(name)
        if policy is None:
            print(missing_head(name))
            continue
        _, task, _, label = HEADS[name]
        for strategy in args.strategies:
            if strategy == "rtc" and not hasattr(policy, "predict_inpainted"):
                continue  # RTC guides an iterative sampler: not ACT
            for d in args.d:
                parts = evaluate_blocks(policy, name, strategy, d, seeds_all, args)
                _record_point(label, task, strategy, d, parts, args, wilson_interval)


def _record_point(label, task, strategy, d, parts, args, wilson_interval) -> None:
    seeds = [s for p in parts for s in p["seeds"]]
    n = len(seeds)
    shown = strategy
    if strategy == "rtc":  # variants get their own rows
        shown += "" if args.prefix == "guide" else f" ({args.prefix} prefix)"
        shown += "" if args.max_guidance == 5.0 else f" (clip {args.max_guidance:g})"
    span = f"{min(seeds)}-{max(seeds)}"
    smooth = mean_smoothness(parts)
    cmd = (f"{COMMAND} --only curves --heads {args.head_of[label]} --strategies {strategy} --d {d} "
           f"--episodes {args.episodes} --seed-start {args.seed_start} --block {args.block}"  # the block size fixes
           # how episodes share a batch and a noise stream, so it is part of what reproduces the number exactly
           f"{f' --max-guidance {args.max_guidance:g} --prefix {args.prefix}' if strategy == 'rtc' else ''}")
    note = (f"{n} held-out seeds{' (REDUCED run: the protocol is 200)' if n < 200 else ''}, sampling seed "
            f"{args.seed}, delay d={d} control steps, strategy {strategy}"
            f"{f', RTC guidance clip {args.max_guidance:g}, prefix {args.prefix}' if strategy == 'rtc' else ''}")
    if task == "pusht":
        value, interval, _, _ = pusht_score(parts)
        record(SECTION, f"{label}, {shown}, d={d}: score", value, "", cmd, note=note, interval=interval, n=n, seeds=span)
    else:
        k = int(sum(x for p in parts for x in p["strict"]))
        lo, hi = wilson_interval(k, n)
        value = round(100.0 * k / n, 1)
        record(SECTION, f"{label}, {shown}, d={d}: strict success", value, "%", cmd, note=note,
               interval=(min(round(100 * lo, 1), value), max(round(100 * hi, 1), value)), n=n, seeds=span)
    unit = "px" if task == "pusht" else "rad"
    record(SECTION, f"{label}, {shown}, d={d}: smoothness",
           f"jump at switches {smooth['switch_jump']:.1f} {unit} (other steps {smooth['other_step']:.1f}), "
           f"max jerk {smooth['max_jerk']:.1f} {unit}/step^3", "", cmd, note=note + "; means over episodes",
           n=n, seeds=span)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=["latency", "curves"], default=None, help="run one part")
    parser.add_argument("--heads", default="dp,flow,act,act-cube", help=f"comma list of {list(HEADS)}")
    parser.add_argument("--strategies", default=",".join(STRATEGY_NAMES), help=f"comma list of {list(STRATEGY_NAMES)}")
    parser.add_argument("--d", default=",".join(map(str, DELAYS)), help="comma list of delays in control steps")
    parser.add_argument("--episodes", type=int, default=200, help="held-out seeds per point (protocol: 200)")
    parser.add_argument("--seed-start", type=int, default=100000, help="first held-out seed (protocol: 100000)")
    parser.add_argument("--block", type=int, default=50, help="seeds per cached block (the unit of resumption)")
    parser.add_argument("--seed", type=int, default=0, help="sampling seed (torch generator of every chunk's noise)")
    parser.add_argument("--max-guidance", type=float, default=5.0, help="RTC's guidance clip beta (paper: 5)")
    parser.add_argument("--prefix", choices=["guide", "replace"], default="guide",
                        help="RTC's frozen prefix: guided (the paper) or also replaced at every step (DP inpainting)")
    parser.add_argument("--repeats", type=int, default=25,
                        help="latency: timed calls per head (median; 25 is steadier than 7 on a shared machine)")
    parser.add_argument("--no-record", action="store_true",
                        help="latency: print only (to see the run-to-run spread without touching the rows)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--cache", default=os.path.join(os.environ.get("XDG_CACHE_HOME", "~/.cache"), "coursekit",
                                                        "bench_latency"), help="where evaluated blocks are kept")
    args = parser.parse_args(argv)
    args.heads = _csv(args.heads, tuple(HEADS))
    args.strategies = _csv(args.strategies, STRATEGY_NAMES)
    args.d = _csv(args.d, None, int)
    if any(d < 0 for d in args.d) or args.episodes < 1 or args.block < 1 or args.threads < 1:
        raise SystemExit(f"need d >= 0, --episodes/--block/--threads >= 1; got d={args.d}, "
                         f"episodes={args.episodes}, block={args.block}, threads={args.threads}")
    if args.seed_start < 100000 or args.seed_start >= 200000:
        print(f"note: seeds from {args.seed_start} are not the reported range (100000+); 200000+ is validation")
    args.head_of = {HEADS[h][3]: h for h in HEADS}
    import torch

    torch.set_num_threads(args.threads)
    if args.only in (None, "latency"):
        part_latency(args)
    if args.only in (None, "curves"):
        part_curves(args)


if __name__ == "__main__":
    main()
