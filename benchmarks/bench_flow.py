"""Flow matching vs Diffusion Policy on PushT: score against integration steps, and chunk latency.

Run: ``.venv/bin/python -m benchmarks.bench_flow`` (about 10 minutes on one thread of a quiet
2-core machine). Parts (``--only``):

- ``score``: the shipped flow checkpoint (``coursekit/checkpoints/pusht_flow_state``) with 1, 2,
  4 and 10 Euler steps (and 2 midpoint steps: 4 U-Net calls, Euler-4's cost, compared with
  Euler-4 on validation seeds 200000.. too) and the shipped Diffusion Policy with DDIM-10, all on the SAME
  ``--episodes`` (default 200) held-out seeds 100000.. and the same sampling seed 0, 300 steps,
  the paper's protocol (mean of max coverage reward; success = coverage > 95 %). 95 % intervals:
  Wilson for success rates, a seeded percentile bootstrap (10,000 resamples of the seeds) for
  mean scores and for the paired difference flow Euler-4 minus DP DDIM-10 (paired: same seeds);
  both from :mod:`coursekit.stats`.
  Each evaluation is cached in ``--out`` as JSON (per-episode max reward and success) and reused
  when the checkpoint file and seeds are unchanged (``--fresh`` re-runs them).
- ``latency``: one chunk at batch 1 (B=1, To observations), median over ``--repeats`` rounds in
  which flow 1/2/4/10 Euler steps, flow midpoint-2, DP DDIM-10 and ACT (``act_pusht``, one pass with z = 0) take
  turns, so that a shared machine's load hits all alike.
- ``shipped``: the flow checkpoint's own default (Euler-10) on ``--episodes`` (default 200) protocol
  seeds, as ``coursekit eval`` runs it, with a bootstrap interval
  (``tests/test_shipped_checkpoints.py`` re-checks the checkpoint episode by episode).
- ``spacing``: chapter 10's question ("can ten steps collapse to one?") on equal terms. The DP
  checkpoint's own DDIM spacing is diffusers' "leading" one, whose single step queries t = 0 and
  so returns near-noise (chapter 4): Euler-1 against that DDIM-1 compares a flow head with a
  handicapped sampler. This part runs DP DDIM-N with "trailing" spacing (N = 1 queries t = 99, the
  noise level the sampler starts from) and with "leading" spacing for N = 1, 2, 4, 10, on the same
  seeds and protocol as ``score`` (DDIM-10 leading is the ``score`` part's DP row, evaluated again
  here so the part stands alone; the two rows agree).

Both checkpoints were trained on the same 400 demonstrations (seeds 0..399, DART noise 0/5 px,
keypoint features), recipe ``cpu`` (lr 5e-4, batch 128), training seed 0; their step counts are
read from the checkpoints and written into every row. Every figure goes through
``benchmarks.results.record(section="Flow matching", ...)``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.results import record
from coursekit.checkpoint import WEIGHTS_FILE, load_checkpoint, read_checkpoint_info
from coursekit.evaluate import evaluate_pusht, heldout_seeds
from coursekit.atomic import atomic_write_text
from coursekit.stats import bootstrap_interval, mean_estimate, rate_estimate
from coursekit.weights_file import file_sha256

COMMAND = ".venv/bin/python -m benchmarks.bench_flow"
SECTION = "Flow matching"
ROOT = Path(__file__).resolve().parent.parent
CKPT = {"flow": ROOT / "coursekit" / "checkpoints" / "pusht_flow_state",
        "diffusion": ROOT / "coursekit" / "checkpoints" / "pusht_diffusion_state",
        "act": ROOT / "coursekit" / "checkpoints" / "act_pusht"}
FLOW_STEPS = (1, 2, 4, 10)


def _weights_hash(checkpoint: Path) -> str:
    return file_sha256(checkpoint / WEIGHTS_FILE)[:16]


def evaluate_cached(checkpoint: Path, sampler: str, steps: int, seeds: list[int], cache: Path,
                    reuse: bool = True, spacing: str | None = None) -> dict:
    """Per-episode max reward and success of (checkpoint, sampler, steps) on ``seeds``; cached as JSON.
    ``spacing``: a DDIM timestep spacing other than the checkpoint's own ("leading" or "trailing")."""
    key = {"checkpoint": str(checkpoint), "weights": _weights_hash(checkpoint), "sampler": sampler,
           "steps": steps, "seeds": list(seeds)}
    if spacing is not None:
        key["spacing"] = spacing
    if reuse and cache.is_file():
        data = json.loads(cache.read_text())
        if all(data.get(k) == v for k, v in key.items()):
            return data
    info = read_checkpoint_info(checkpoint)
    policy = load_checkpoint(checkpoint, device="cpu")
    if spacing is not None:
        policy = policy.with_config(ddim_timestep_spacing=spacing)
    t0 = time.perf_counter()
    r = evaluate_pusht(policy, seeds=seeds, sampler=sampler, num_inference_steps=steps,
                       dataset_meta=info.get("dataset"), progress=False)
    data = {**key, "max_reward": [float(v) for v in np.asarray(r.max_reward)],
            "success": [bool(v) for v in np.asarray(r.success)], "seconds": round(time.perf_counter() - t0, 1),
            "torch_threads": torch.get_num_threads()}
    cache.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(cache, json.dumps(data) + "\n")
    return data


def training_note(checkpoint: Path) -> str:
    """'<steps> steps (<a> + <b> warm-started), batch B, lr L, seed S' from the checkpoint's summary."""
    t = read_checkpoint_info(checkpoint)["training"]
    prior = t.get("init_from") or {}
    cfg = t["train_config"]
    total = t["steps"] + (prior.get("steps") or 0)
    parts = f" ({prior['steps']} + {t['steps']}, warm-started)" if prior.get("steps") else ""
    return f"{total} steps{parts}, batch {cfg['batch_size']}, lr {cfg['lr']:g}, seed {cfg['seed']}"


def _label(kind: str, sampler: str, n: int) -> str:
    if kind == "diffusion":
        return "DP score, DDIM-10 (same seeds as flow)"
    return f"flow matching score, Euler-{n}" if sampler == "euler" else f"flow matching score, midpoint-{n} ({2 * n} U-Net calls)"


def part_score(args: argparse.Namespace, rec) -> None:
    seeds = heldout_seeds(args.episodes)
    variants = [("flow", "euler", n) for n in FLOW_STEPS] + [("flow", "midpoint", 2), ("diffusion", "ddim", 10)]
    res = {}
    for kind, sampler, n in variants:
        d = evaluate_cached(CKPT[kind], sampler, n, seeds, args.out / f"eval_{kind}_{sampler}{n}_{args.episodes}.json",
                            reuse=not args.fresh)
        res[(kind, sampler, n)] = d
        print(f"{kind:9s} {sampler}-{n:<2d}: score {np.mean(d['max_reward']):.3f}, success {np.mean(d['success']):.0%} "
              f"({d['seconds']:.0f} s on {d['torch_threads']} thread(s))")
    # The higher-order variant at Euler-4's cost (midpoint-2 = 4 U-Net calls) is compared on
    # VALIDATION seeds (200000+), the protocol's place for choosing variants; both are reported.
    val_seeds = heldout_seeds(args.episodes, 200000)
    val = {s_n: np.mean(evaluate_cached(CKPT["flow"], s_n[0], s_n[1], val_seeds,
                                        args.out / f"eval_flow_{s_n[0]}{s_n[1]}_{args.episodes}_val.json",
                                        reuse=not args.fresh)["max_reward"])
           for s_n in (("euler", 4), ("midpoint", 2))}
    val_note = (f"validation seeds {val_seeds[0]}-{val_seeds[-1]}: midpoint-2 {val[('midpoint', 2)]:.3f} vs "
                f"Euler-4 {val[('euler', 4)]:.3f}")
    print(val_note)
    trained = f"flow trained {training_note(CKPT['flow'])}; DP trained {training_note(CKPT['diffusion'])}"
    common = (f"{args.episodes} held-out seeds {seeds[0]}..{seeds[-1]} (the same for every row), sampling seed 0, "
              f"300 steps; 400 demos (DART 0/5 px), keypoint features, U-Net 64/128/256, recipe cpu; {trained}")
    seed_range = f"{seeds[0]}-{seeds[-1]}"
    for (kind, sampler, n), d in res.items():
        score = mean_estimate(d["max_reward"])
        rate = rate_estimate(np.asarray(d["success"], dtype=bool))
        calls = 2 * n if sampler == "midpoint" else n
        extra = f"; {val_note}" if sampler == "midpoint" else ""
        rec(SECTION, _label(kind, sampler, n), round(score.value, 3), "", f"{COMMAND} --only score",
            target=">= DP DDIM-10 - 0.03" if (kind, sampler, n) == ("flow", "euler", 4) else "",
            note=f"success {rate.value:.1%} (Wilson 95 % {rate.lo:.1%}-{rate.hi:.1%}); {calls} U-Net call(s) per chunk"
                 f"{extra}; {common}",
            interval=(round(score.lo, 3), round(score.hi, 3)), n=score.n, seeds=seed_range)
    ddim = np.asarray(res[("diffusion", "ddim", 10)]["max_reward"])
    for sampler, n, name in (("euler", 4, "flow Euler-4"), ("midpoint", 2, "flow midpoint-2 (4 calls)")):
        diff = np.asarray(res[("flow", sampler, n)]["max_reward"]) - ddim
        lo, hi = bootstrap_interval(diff)
        print(f"{name} minus DP DDIM-10: {diff.mean():+.3f} (95 % CI {lo:+.3f} .. {hi:+.3f}, paired)")
        rec(SECTION, f"{name} minus DP DDIM-10 score", round(float(diff.mean()), 3), "", f"{COMMAND} --only score",
            target=">= -0.03" if sampler == "euler" else "",
            note=f"paired over the same seeds (bootstrap of per-seed differences); {common}",
            interval=(round(lo, 3), round(hi, 3)), n=len(diff), seeds=seed_range)


def _chunk_call(policy, kind: str, n: int | None, sampler: str | None = None):
    c = policy.config
    obs = torch.zeros(1, c.n_obs_steps, c.obs_dim)  # (B=1, To, Do)
    g = torch.Generator().manual_seed(0)
    if kind == "act":
        return lambda: policy.predict_chunk(obs)
    sampler = sampler or ("euler" if kind == "flow" else "ddim")
    return lambda: policy.predict_chunk(obs, sampler=sampler, num_inference_steps=n, generator=g)


def part_latency(args: argparse.Namespace, rec) -> None:
    policies = {k: load_checkpoint(CKPT[k], device="cpu") for k in ("flow", "diffusion", "act")}
    calls = {f"flow Euler-{n}": _chunk_call(policies["flow"], "flow", n) for n in FLOW_STEPS}
    calls["flow midpoint-2"] = _chunk_call(policies["flow"], "flow", 2, sampler="midpoint")
    calls["DP DDIM-10"] = _chunk_call(policies["diffusion"], "diffusion", 10)
    calls["ACT (one pass, z = 0)"] = _chunk_call(policies["act"], "act", None)
    times: dict[str, list[float]] = {k: [] for k in calls}
    load = os.getloadavg()[0]
    with torch.no_grad():
        for fn in calls.values():  # warm-up
            fn()
        for _ in range(args.repeats):  # take turns: the machine's load hits every variant alike
            for name, fn in calls.items():
                t0 = time.perf_counter()
                fn()
                times[name].append(1e3 * (time.perf_counter() - t0))
    med = {k: statistics.median(v) for k, v in times.items()}
    for k, v in med.items():
        print(f"{k:24s} {v:7.1f} ms per chunk (median of {args.repeats}; min {min(times[k]):.1f})")
    ratio = med["DP DDIM-10"] / med["flow Euler-4"]
    print(f"DDIM-10 / flow Euler-4 latency: {ratio:.2f}x")
    note = (f"batch 1, one chunk (Tp=16 for DP/flow, k=20 for ACT), median of {args.repeats} rounds taking turns, "
            f"{torch.get_num_threads()} torch thread(s), 1-min load average {load:.1f} on {os.cpu_count()} cores at start")
    for k, v in med.items():
        rec(SECTION, f"chunk latency, {k}", round(v, 1), "ms", f"{COMMAND} --only latency", note=note)
    rec(SECTION, "latency ratio DP DDIM-10 / flow Euler-4", round(ratio, 2), "x", f"{COMMAND} --only latency",
        target=">= 2x", note="same run; " + note)


def part_shipped(args: argparse.Namespace, rec) -> None:
    seeds = heldout_seeds(args.episodes)
    d = evaluate_cached(CKPT["flow"], None, None, seeds, args.out / f"eval_flow_default_{args.episodes}.json",
                        reuse=not args.fresh)
    score = mean_estimate(d["max_reward"])
    rate = rate_estimate(np.asarray(d["success"], dtype=bool))
    print(f"shipped flow (its default, Euler-10), {args.episodes} seeds: score {score}, success {rate}")
    rec(SECTION, "shipped flow checkpoint score, Euler-10 (notebook 10)", round(score.value, 3), "",
        f"{COMMAND} --only shipped --episodes {args.episodes} --threads {args.threads}",
        note=f"success {rate.value:.1%} (Wilson 95 % {rate.lo:.1%}-{rate.hi:.1%}); {args.episodes} held-out seeds from "
             f"100000, 300 steps, the checkpoint's default sampler; "
             f"trained {training_note(CKPT['flow'])} (float16 weights); evaluated with {d['torch_threads']} torch "
             f"thread(s); the checkpoint's own sampler, as `coursekit eval` runs it",
        interval=(round(score.lo, 3), round(score.hi, 3)), n=score.n, seeds=f"{seeds[0]}-{seeds[-1]}")


SPACING_STEPS = (1, 2, 4, 10)


def part_spacing(args: argparse.Namespace, rec) -> None:
    seeds = heldout_seeds(args.episodes)
    policy = load_checkpoint(CKPT["diffusion"], device="cpu")
    common = (f"{args.episodes} held-out seeds {seeds[0]}..{seeds[-1]} (the flow rows' seeds), sampling seed 0, 300 steps; "
              f"the shipped DP checkpoint (trained {training_note(CKPT['diffusion'])}), its DDIM spacing overridden")
    for spacing in ("trailing", "leading"):
        for n in SPACING_STEPS:
            d = evaluate_cached(CKPT["diffusion"], "ddim", n, seeds,
                                args.out / f"eval_diffusion_ddim{n}_{spacing}_{args.episodes}.json",
                                reuse=not args.fresh, spacing=spacing)
            walked = policy.with_config(ddim_timestep_spacing=spacing).make_sampler("ddim", n).timesteps
            score = mean_estimate(d["max_reward"])
            rate = rate_estimate(np.asarray(d["success"], dtype=bool))
            print(f"DP DDIM-{n:<2d} {spacing:8s} t = {[int(t) for t in walked]}: score {score}, success {rate.value:.0%} "
                  f"({d['seconds']:.0f} s)")
            rec(SECTION, f"DP score, DDIM-{n}, {spacing} spacing", round(score.value, 3), "", f"{COMMAND} --only spacing",
                note=f"success {rate.value:.1%} (Wilson 95 % {rate.lo:.1%}-{rate.hi:.1%}); timesteps walked "
                     f"{', '.join(str(int(t)) for t in walked)}; {n} U-Net call(s) per chunk; {common}",
                interval=(round(score.lo, 3), round(score.hi, 3)), n=score.n, seeds=f"{seeds[0]}-{seeds[-1]}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=["score", "latency", "shipped", "spacing"], default=None, help="run one part")
    parser.add_argument("--episodes", type=int, default=200, help="held-out episodes of the score, shipped and spacing parts (default 200)")
    parser.add_argument("--repeats", type=int, default=30, help="latency rounds (default 30)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_flow", help="evaluation cache directory")
    parser.add_argument("--fresh", action="store_true", help="re-run evaluations even if cached")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")
    args = parser.parse_args(argv)
    if args.episodes < 2 or args.repeats < 1 or args.threads < 1:
        raise SystemExit(f"need --episodes >= 2, --repeats >= 1, --threads >= 1; got {args.episodes}, "
                         f"{args.repeats}, {args.threads}")
    torch.set_num_threads(args.threads)
    rec = (lambda *a, **k: None) if args.no_record else record  # noqa: E731
    missing = [str(p) for p in CKPT.values() if not (p / "config.json").is_file()]
    if missing:
        raise SystemExit(f"missing checkpoints: {missing}")
    for name, part in (("score", part_score), ("latency", part_latency), ("shipped", part_shipped),
                       ("spacing", part_spacing)):
        if args.only in (None, name):
            part(args, rec)


if __name__ == "__main__":
    main()
