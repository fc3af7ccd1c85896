"""Chapter 1's averaging failure, measured: one start, two routes, regression vs Diffusion Policy.

    .venv/bin/python -m benchmarks.bench_two_route                       # 3 training seeds x 200 starts (~1 h, 1 core)
    .venv/bin/python -m benchmarks.bench_two_route --steps 50 --rollouts 2 --no-record   # smoke

Why this set-up: on the whole task each start is demonstrated once, so a chunked regressor can
(and, measured in "Claims (PushT, shipped checkpoints)", does) learn a committed side per start;
MSE's averaging bites where the SAME situation was demonstrated both ways. Chapter 1 builds that
case on purpose (Chi et al. 2023, Sec. 1 and Fig. 3 make the same argument): ``--runs-each``
clockwise and as many anticlockwise expert runs from ``TWO_WAY_START`` (they differ only in the
planner's seeded coin), nothing else. On exactly these demonstrations, with one U-Net backbone
(down_dims ``--down-dims``, To = 2, Tp = 16, Ta = 8, keypoint features, recipe "cpu",
``--steps`` optimiser steps), train chunked regression and Diffusion Policy (DDIM-10) with each of
``--train-seeds`` and measure from ``TWO_WAY_START``:

- from each of ``--rollouts`` starts near it (the pusher moved by up to ``--jitter`` px, block
  untouched; the same starts, seeded, for every head and training seed): the first chunk (DP:
  sampled, a different stream per start), and which of three reference paths it is nearest (RMS
  over its targets from the current step on): the mean first chunk of the clockwise runs, of the
  anticlockwise runs, or of all runs, the path between the two routes that MSE's optimum predicts
  (chapter 1, 5a). A turning-angle test does not work here: a straight path through the T sweeps
  a large angle about its centre too;
- from the same starts, closed-loop episodes of 300 steps: score (max coverage, the paper's
  metric), success, and steps stalled against the T (``coursekit.evaluate.behaviour``). The
  jitter is what makes a deterministic regressor's rollouts more than one episode: from the
  exact start all of them would be the same.

Rows go to the section "Claims (PushT, two-route start)" with a t-interval over training seeds
(scores) or a Wilson interval over the pooled first chunks (paths).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import gymnasium as gym
import numpy as np

from benchmarks.protocol import t_estimate
from benchmarks.resumable import cache_dir

SECTION = "Claims (PushT, two-route start)"
CACHE = cache_dir("two_route")
"""The trained models and per-start results (outside the repository; an existing one is reused)."""
PATHS = ("cw", "ccw", "between")
HEADS = {"chunked regression": ("regression", {}), "DP DDIM-10": ("diffusion", {"sampler": "ddim", "num_inference_steps": 10})}
"""row label -> (policy type, sampling options)."""


def two_route_runs(runs_each: int) -> tuple[list, list[int]]:
    """``runs_each`` clockwise then as many anticlockwise expert runs from TWO_WAY_START, and their coin seeds."""
    from coursekit.experts.pusht_planner import TWO_WAY_START
    from coursekit.tasks import PUSHT
    from coursekit.viz.expert_plots import expert_runs_from

    picked: dict[str, list] = {"cw": [], "ccw": []}
    for coin in range(20 * runs_each):
        (rec,) = expert_runs_from(TWO_WAY_START, coin_seeds=[coin])
        side = rec.route_choices[0]["taken"] if rec.route_choices else None
        if side in picked and len(picked[side]) < runs_each and rec.success_step is not None:
            picked[side].append((coin, rec))
        if all(len(v) == runs_each for v in picked.values()):
            break
    if not all(len(v) == runs_each for v in picked.values()):
        raise RuntimeError(f"found {len(picked['cw'])} cw / {len(picked['ccw'])} ccw successful runs in "
                           f"{20 * runs_each} coin seeds; ask for fewer --runs-each")
    chosen = picked["cw"] + picked["ccw"]
    return [r for _, r in chosen], [c for c, _ in chosen]


class ResetToStarts(gym.Wrapper):
    """PushT that resets episode ``seed`` to ``starts[seed]`` (the evaluation's seeds index the starts)."""

    def __init__(self, env: gym.Env, starts: np.ndarray) -> None:
        super().__init__(env)
        self.starts = np.asarray(starts, dtype=float)  # (N, 5) [agent x, y, block x, y, angle]

    def reset(self, *, seed=None, options=None):
        return self.env.reset(seed=seed, options={"reset_to_state": self.starts[seed].tolist()})


def jittered_starts(n: int, jitter: float, seed: int = 0) -> np.ndarray:
    """(n, 5) states: TWO_WAY_START with the pusher moved uniformly within a disc of ``jitter`` px."""
    from coursekit.experts.pusht_planner import TWO_WAY_START

    rng = np.random.default_rng(seed)
    radius = jitter * np.sqrt(rng.uniform(size=n))  # uniform over the disc's area
    angle = rng.uniform(0.0, 2 * np.pi, size=n)
    starts = np.tile(np.asarray(TWO_WAY_START, dtype=float), (n, 1))  # (n, 5)
    starts[:, 0] += radius * np.cos(angle)
    starts[:, 1] += radius * np.sin(angle)
    return starts


def reference_paths(runs: list, horizon: int) -> dict[str, np.ndarray]:
    """{"cw", "ccw", "between"}: mean first ``horizon`` targets (horizon, 2) of each side's runs, and of all."""
    sides = [r.route_choices[0]["taken"] for r in runs]
    firsts = np.stack([r.actions[:horizon] for r in runs])  # (R, horizon, 2)
    return {"cw": firsts[[s == "cw" for s in sides]].mean(0), "ccw": firsts[[s == "ccw" for s in sides]].mean(0),
            "between": firsts.mean(0)}


def nearest_path(chunks: np.ndarray, refs: dict[str, np.ndarray]) -> list[str]:
    """Name of the reference path nearest (RMS) to each chunk (B, H, 2)."""
    names = list(refs)
    dist = np.stack([np.sqrt(((chunks - refs[k][None]) ** 2).sum(-1).mean(-1)) for k in names], axis=1)  # (B, 3)
    return [names[i] for i in dist.argmin(1)]


def first_chunks(policy, sampling: dict, starts: np.ndarray, seed: int) -> np.ndarray:
    """(N, Tp - To + 1, 2): the first chunk from each start, from the current step on (DP: one sample each)."""
    import torch

    from coursekit.data.features import get_features
    from coursekit.envs.pusht import PushTEnv

    env = PushTEnv(obs_type="state")
    feats = []
    for start in starts:
        obs, _ = env.reset(options={"reset_to_state": start.tolist()})
        feats.append(get_features(policy.config.features)(obs))  # (Do,)
    to = policy.config.n_obs_steps
    history = np.repeat(np.stack(feats)[:, None], to, axis=1)  # (N, To, Do): as at an episode's start
    chunks = policy.predict_chunk(history, generator=torch.Generator().manual_seed(seed), **sampling)
    return np.asarray(chunks)[:, to - 1:]


def measure(policy, sampling: dict, runs: list, starts: np.ndarray, seed: int) -> dict:
    """First-chunk paths and closed-loop outcomes of ``policy`` from each of ``starts`` (module docstring)."""
    from coursekit.evaluate.behaviour import stalled_steps
    from coursekit.evaluate.closed_loop import evaluate
    from coursekit.evaluate.tasks import RecordAdapter
    from coursekit.tasks import PUSHT

    chunks = first_chunks(policy, sampling, starts, seed)
    paths = nearest_path(chunks, reference_paths(runs, chunks.shape[1]))

    class JitteredAdapter(RecordAdapter):  # PushT as usual, but episode i starts at starts[i]
        def make_env(self, max_steps: int):
            return ResetToStarts(super().make_env(max_steps), starts)

    r = evaluate(policy, JitteredAdapter(PUSHT, policy), seeds=list(range(len(starts))), sampling=sampling, seed=seed,
                 progress=False, record=True)
    stall = stalled_steps(r.states, r.length)
    return {"paths": paths, "max_reward": r.max_reward.tolist(), "success": r.success.tolist(),
            "stalled": stall.tolist(), "seconds": r.seconds}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line, checked (a bad value exits with a line that names it)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs-each", type=int, default=6, help="expert runs per side from TWO_WAY_START (chapter 1: 6)")
    parser.add_argument("--train-seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=1500, help="optimiser steps per model")
    parser.add_argument("--down-dims", type=int, nargs="+", default=[32, 64, 128], help="U-Net widths (both heads)")
    parser.add_argument("--rollouts", type=int, default=200,
                        help="starts near TWO_WAY_START per training seed: one first chunk and one episode each")
    parser.add_argument("--jitter", type=float, default=5.0, help="px: the pusher's start lies within this of TWO_WAY_START's")
    parser.add_argument("--out", type=Path, default=CACHE, help=f"models and results (default {CACHE})")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")
    args = parser.parse_args(argv)
    for flag in ("runs_each", "steps", "rollouts", "threads"):
        if getattr(args, flag) < 1:
            raise SystemExit(f"--{flag.replace('_', '-')} must be >= 1, got {getattr(args, flag)}")
    if not 0.0 <= args.jitter <= 20.0:
        raise SystemExit(f"--jitter must be in [0, 20] px (the start must stay the two-way one), got {args.jitter}")
    return args


def measure_heads(args: argparse.Namespace, runs: list, data) -> dict[str, list[dict]]:
    """label -> one :func:`measure` result per training seed: each head trained (or loaded) on ``data``
    and measured from the jittered starts; every result is cached in its run folder."""
    from benchmarks.resumable import load_or_train
    from coursekit.atomic import atomic_write_text
    from coursekit.nn.unet1d import UNet1DConfig
    from coursekit.policies import make_policy

    tag = f"runs{args.runs_each}_s{args.steps}_u{'-'.join(map(str, args.down_dims))}"
    starts = jittered_starts(args.rollouts, args.jitter)
    results: dict[str, list[dict]] = {}
    for label, (kind, sampling) in HEADS.items():
        for ts in args.train_seeds:
            run = args.out / f"{kind}_{tag}_seed{ts}"
            file = run / f"two_route_starts{args.rollouts}_jitter{args.jitter:g}.json"
            if file.exists():
                results.setdefault(label, []).append(json.loads(file.read_text()))
                continue
            policy = load_or_train(run, lambda: make_policy(kind, data, features="pusht_keypoints", recipe="cpu", seed=ts,
                                                            unet=UNet1DConfig(down_dims=tuple(args.down_dims))),
                                   args.steps, ts, args.threads, data.meta)
            out = measure(policy, sampling, runs, starts, seed=ts)
            atomic_write_text(file, json.dumps(out) + "\n")
            results.setdefault(label, []).append(out)
            print(f"{label}, training seed {ts}: first chunks {dict((s, out['paths'].count(s)) for s in PATHS)}"
                  f"; score {np.mean(out['max_reward']):.3f}, stalled {np.mean(out['stalled']):.1f} steps", flush=True)
    return results


def record_rows(args: argparse.Namespace, results: dict[str, list[dict]], n_runs: int) -> None:
    """Per head: the share of first chunks between the routes (Wilson), the score and the steps
    stalled (t-intervals over training seeds); printed, and recorded unless ``--no-record``."""
    from coursekit.stats import rate_estimate

    cmd = (f".venv/bin/python -m benchmarks.bench_two_route --runs-each {args.runs_each} --steps {args.steps} "
           f"--down-dims {' '.join(map(str, args.down_dims))} --train-seeds {' '.join(map(str, args.train_seeds))} "
           f"--rollouts {args.rollouts} --jitter {args.jitter:g} --threads {args.threads}")
    where = f"{args.rollouts} starts within {args.jitter:g} px of TWO_WAY_START; training seeds {args.train_seeds[0]}-{args.train_seeds[-1]}"
    conditions = (f"{args.rollouts} starts (pusher within {args.jitter:g} px of TWO_WAY_START's, block as there) per "
                  f"training seed; trained on {n_runs} expert runs from TWO_WAY_START ({args.runs_each} cw + {args.runs_each} ccw) and "
                  f"nothing else; U-Net {args.down_dims}, To=2, Tp=16, Ta=8, keypoints, recipe cpu, {args.steps} "
                  f"steps; {len(args.train_seeds)} training seed(s) {args.train_seeds}")

    def rec(name, value, lo, hi, n, note):
        print(f"  {name}: {value:.3f} [{lo:.3f}, {hi:.3f}] (n={n}); {note}", flush=True)
        if not args.no_record:
            from benchmarks.results import record

            v = round(value, 3)
            record(SECTION, name, v, "", cmd, note=note, interval=(min(round(lo, 3), v), max(round(hi, 3), v)),
                   n=n, seeds=where)

    for label, outs in results.items():
        paths = np.array([s for o in outs for s in o["paths"]])
        est = rate_estimate(paths == "between")
        per_chunk = "its deterministic chunk" if label == "chunked regression" else "one sampled chunk"
        rec(f"{label}: first chunk nearest the path between the routes", est.value, est.lo, est.hi, est.n,
            f"share of first chunks ({per_chunk} per start, pooled over starts and training seeds; Wilson interval) "
            f"nearer the mean of all "
            f"expert first chunks than the mean cw one ({np.mean(paths == 'cw'):.2f}) or the mean ccw one "
            f"({np.mean(paths == 'ccw'):.2f}); {conditions}")
        for figure, key in (("score", "max_reward"), ("steps stalled against the T", "stalled")):
            per_seed = [float(np.mean(o[key])) for o in outs]
            mean, lo, hi = t_estimate(per_seed)
            lo, hi = max(0.0, lo), (min(1.0, hi) if figure == "score" else hi)  # neither can be negative
            rec(f"{label}: {figure} from starts near TWO_WAY_START", mean, lo, hi, sum(len(o[key]) for o in outs),
                f"mean over training seeds (per seed: {', '.join(f'{v:.3f}' for v in per_seed)}), each the mean of "
                f"{len(outs[0][key])} episode(s) of 300 steps; 95 % t-interval over training seeds; {conditions}")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    import torch

    from coursekit.data.episodes import EpisodeDataset
    from coursekit.tasks import PUSHT

    torch.set_num_threads(args.threads)
    runs, coins = two_route_runs(args.runs_each)
    data = EpisodeDataset.from_episodes([{"state": r.states, "action": r.actions, "coverage": r.coverage,
                                          "phase": r.phases} for r in runs],
                                        {"env_id": PUSHT.gym_id, "obs_type": "state", "episode_seeds": [],
                                         "two_route_coin_seeds": coins})
    print(f"{len(runs)} expert runs from TWO_WAY_START (coin seeds {coins}): {data.n_steps} steps", flush=True)
    record_rows(args, measure_heads(args, runs, data), len(runs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
