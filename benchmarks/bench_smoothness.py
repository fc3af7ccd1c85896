"""Temporal ensembling's smoothness as a number: jerk of ACT's executed joint targets on transfer cube.

    .venv/bin/python -m benchmarks.bench_smoothness --episodes 20 --threads 1
    .venv/bin/python -m benchmarks.bench_smoothness --episodes 2 --no-record      # smoke run

Zhao et al. (2023, Sec. IV-A) introduce temporal ensembling to avoid the jerky motion of
executing chunks open loop (a jump every k steps, where one chunk hands over to the next).
The shipped ACT (``coursekit/checkpoints/act_transfer_cube``, k = 100, one training seed) runs
the same held-out episodes (seeds from ``--seed-start``, 400 steps at 50 Hz) with:

- open-loop chunks (receding horizon, Ta = k) and a chunk every step without ensembling (Ta = 1);
- temporal ensembling with m in ``--decays`` (w_i = exp(-m i), oldest chunk first; m = 0.01 is ACT's).

Per episode: the RMS third difference of the 12 arm-joint targets (grippers left out: their
commands are open/close steps by design), in rad/s^3 (``coursekit.evaluate.behaviour.rms_jerk``,
divided by CONTROL_DT^3), over the steps the episode ran; the row is the mean over episodes with
a bootstrap 95 % interval, the note has the strict success of the same episodes (Wilson).
Per-episode values are saved to ``--out``. Rows: section "Claims (arm pair, shipped checkpoints)".
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.protocol import add_protocol_args, protocol_seeds

SECTION = "Claims (arm pair, shipped checkpoints)"
ROOT = Path(__file__).resolve().parent.parent
ARM_JOINTS = (0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12)
"""Action dimensions of the two arms' joints ([left 6, left gripper, right 6, right gripper])."""


def executors(k: int, decays: list[float]) -> dict:
    from coursekit.execution.ensembling import TemporalEnsemble
    from coursekit.execution.receding import RecedingHorizon

    out = {f"open-loop chunks (Ta=k={k})": lambda pc: RecedingHorizon(pc, 1, k),
           "a new chunk every step, no ensembling (Ta=1)": lambda pc: RecedingHorizon(pc, 1, 1)}
    for m in decays:
        out[f"temporal ensembling m={m:g}"] = lambda pc, m=m: TemporalEnsemble(pc, 1, ensemble_decay=m)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_protocol_args(parser, episodes=200, what="per executor")
    parser.add_argument("--decays", type=float, nargs="+", default=[0.0, 0.01, 0.1, 1.0], help="ensembling m values")
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_smoothness", help="per-episode results")
    args = parser.parse_args(argv)
    seeds = protocol_seeds(args)
    from coursekit.checkpoint import find_checkpoint, load_checkpoint, read_checkpoint_info
    from coursekit.envs.aloha.model import CONTROL_DT
    from coursekit.evaluate import evaluate_aloha
    from coursekit.evaluate.behaviour import rms_jerk
    from coursekit.stats import mean_estimate, rate_estimate

    path = find_checkpoint("act_transfer_cube")
    if path is None:
        raise SystemExit("no shipped checkpoint 'act_transfer_cube'")
    policy, meta = load_checkpoint(path, device="cpu"), read_checkpoint_info(path)["dataset"]
    seeds_txt = f"{seeds[0]}-{seeds[-1]}"
    args.out.mkdir(parents=True, exist_ok=True)
    cmd = (f".venv/bin/python -m benchmarks.bench_smoothness --episodes {args.episodes} --seed-start {args.seed_start}"
           f" --decays {' '.join(f'{m:g}' for m in args.decays)} --threads {args.threads}")
    for name, factory in executors(policy.config.chunk_size, args.decays).items():
        file = args.out / f"{name.split(' (')[0].replace(' ', '_').replace('=', '')}_{seeds[0]}_{len(seeds)}.json"
        if file.exists():
            saved = json.loads(file.read_text())
            jerk, strict = np.asarray(saved["jerk"]), np.asarray(saved["strict_success"], dtype=bool)
        else:
            r = evaluate_aloha(policy, "transfer_cube", seeds=seeds, executor_factory=factory, dataset_meta=meta,
                               progress=False)
            jerk = rms_jerk(r.actions, r.length, dims=ARM_JOINTS) / CONTROL_DT**3  # (N,) rad/s^3
            strict = r.states[:, -1, 1] > 0.5
            file.write_text(json.dumps({"seeds": seeds, "jerk": jerk.tolist(), "strict_success": strict.tolist(),
                                        "length": r.length.tolist(), "seconds": r.seconds}) + "\n")
        est, ok = mean_estimate(jerk), rate_estimate(strict)
        print(f"{name}: RMS jerk {est} rad/s^3; strict success {ok}", flush=True)
        if not args.no_record:
            from benchmarks.results import record

            record(SECTION, f"ACT transfer cube RMS jerk of joint targets, {name}", est.value, "rad/s^3",
                   cmd, note=f"12 arm joints, third difference / CONTROL_DT^3, mean over episodes; strict success "
                             f"{ok}; shipped checkpoint, one training seed",
                   interval=(est.lo, est.hi), n=est.n, seeds=seeds_txt)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
