"""Flow matching vs Diffusion Policy on PushT: score vs integration steps, and chunk latency.

(Work in progress: the evaluation cache is written first so the long evaluations can start.)
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from coursekit.checkpoint import load_checkpoint, read_checkpoint_info
from coursekit.evaluate import evaluate_pusht, heldout_seeds
from coursekit.io import atomic_write_text

ROOT = Path(__file__).resolve().parent.parent
CKPT = {"flow": ROOT / "coursekit" / "checkpoints" / "pusht_flow_state",
        "diffusion": ROOT / "coursekit" / "checkpoints" / "pusht_diffusion_state",
        "act": ROOT / "coursekit" / "checkpoints" / "act_pusht"}


def evaluate_cached(checkpoint: Path, sampler: str, steps: int, seeds: list[int], cache: Path,
                    reuse: bool = True) -> dict:
    """Per-episode max reward and success of one (checkpoint, sampler, steps) on ``seeds``; cached as JSON."""
    if reuse and cache.is_file():
        data = json.loads(cache.read_text())
        if data["seeds"] == list(seeds) and data["checkpoint"] == str(checkpoint):
            return data
    info = read_checkpoint_info(checkpoint)
    policy = load_checkpoint(checkpoint, device="cpu")
    t0 = time.perf_counter()
    r = evaluate_pusht(policy, seeds=seeds, sampler=sampler, num_inference_steps=steps,
                       dataset_meta=info.get("dataset"), progress=False)
    data = {"checkpoint": str(checkpoint), "sampler": sampler, "steps": steps, "seeds": list(seeds),
            "max_reward": [float(v) for v in np.asarray(r.max_reward)], "success": [bool(v) for v in np.asarray(r.success)],
            "seconds": time.perf_counter() - t0, "ms_per_chunk": r.ms_per_chunk, "torch_threads": torch.get_num_threads()}
    cache.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(cache, json.dumps(data) + "\n")
    return data


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eval-one", nargs=2, metavar=("POLICY", "SAMPLER:STEPS"), default=None)
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_flow")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    seeds = heldout_seeds(args.episodes)
    if args.eval_one:
        kind, spec = args.eval_one
        sampler, steps = spec.split(":")
        d = evaluate_cached(CKPT[kind], sampler, int(steps), seeds, args.out / f"eval_{kind}_{sampler}{steps}_{args.episodes}.json")
        print(f"{kind} {sampler}-{steps}: score {np.mean(d['max_reward']):.3f} success {np.mean(d['success']):.2f} "
              f"in {d['seconds']:.0f} s")


if __name__ == "__main__":
    main()
