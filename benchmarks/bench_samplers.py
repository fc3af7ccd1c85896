"""Sampler latency: one action chunk at batch 1, DDIM-10 vs DDPM-100, side by side in one run.

Run: ``.venv/bin/python -m benchmarks.bench_samplers``. Network: the CPU-default conditional U-Net
(down_dims 64/128/256, Da = 2, global condition = To x 6 PushT features = 12), randomly initialised
(latency does not depend on the weights). The two samplers alternate within each repeat so that the
machine's load (2 cores shared) hits both alike; the best (minimum) over repeats is reported, the
least-disturbed measurement on a shared machine, with the median printed alongside.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import torch

from benchmarks.results import record
from coursekit.diffusion import DDIMSampler, DDPMSampler, NoiseSchedule
from coursekit.nn import ConditionalUnet1D, UNet1DConfig

COMMAND = ".venv/bin/python -m benchmarks.bench_samplers"
SECTION = "Samplers"


def chunk_ms(sampler, net, cond, shape, seed: int) -> float:
    """Wall-clock milliseconds for one full chunk (all denoising steps)."""
    g = torch.Generator().manual_seed(seed)
    t0 = time.perf_counter()
    sampler.sample(net, shape, cond=cond, generator=g)
    return (time.perf_counter() - t0) * 1e3


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="alternating DDIM/DDPM repeats (best reported)")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch threads (default: torch's own choice); recorded with the result")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")
    args = parser.parse_args(argv)
    if args.threads is not None:
        if args.threads < 1:
            raise SystemExit(f"--threads must be >= 1, got {args.threads}")
        torch.set_num_threads(args.threads)
    command = COMMAND + (f" --threads {args.threads}" if args.threads is not None else "")

    torch.manual_seed(0)
    Tp, Da, To, obs_dim = 16, 2, 2, 6
    net = ConditionalUnet1D(Da, To * obs_dim, UNet1DConfig.preset("cpu")).eval()
    cond = torch.randn(1, To * obs_dim)
    schedule = NoiseSchedule(num_train_timesteps=100)
    ddim, ddpm = DDIMSampler(schedule, num_inference_steps=10), DDPMSampler(schedule)
    shape = (1, Tp, Da)
    for _ in range(3):  # warm-up (allocator, thread pool)
        chunk_ms(ddim, net, cond, shape, 0)
    ddim_ms, ddpm_ms = [], []
    for r in range(args.repeats):
        ddim_ms.append(chunk_ms(ddim, net, cond, shape, r))
        ddpm_ms.append(chunk_ms(ddpm, net, cond, shape, r))
    ddim_best, ddpm_best = min(ddim_ms), min(ddpm_ms)
    speedup = ddpm_best / ddim_best
    n_params = sum(p.numel() for p in net.parameters())
    print(f"U-Net cpu preset: {n_params / 1e6:.2f} M params, torch threads = {torch.get_num_threads()}")
    for name, times in (("DDIM-10 ", ddim_ms), ("DDPM-100", ddpm_ms)):
        print(f"{name} chunk: best {min(times):7.1f} ms, median {statistics.median(times):7.1f} ms "
              f"(all: {', '.join(f'{x:.0f}' for x in times)})")
    print(f"speed-up DDIM-10 over DDPM-100: {speedup:.1f}x")
    print(f"1-min load average: {os.getloadavg()[0]:.1f}")
    if args.no_record:
        return
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    note = (f"batch 1, Tp={Tp}, Da={Da}, cpu U-Net ({n_params / 1e6:.2f} M), best of {args.repeats} "
            f"alternating repeats, {torch.get_num_threads()} torch threads, 1-min load average {load:.1f} "
            f"on {os.cpu_count()} cores while measuring")
    record(SECTION, "DDIM-10 chunk latency (batch 1)", round(ddim_best, 1), "ms", command, target="< 60 ms", note=note)
    record(SECTION, "DDPM-100 chunk latency (batch 1)", round(ddpm_best, 1), "ms", command, note=note)
    record(SECTION, "DDIM-10 speed-up over DDPM-100", round(speedup, 1), "x", command, target=">= 8x",
           note="same run, same network, " + note)
    record(SECTION, "U-Net denoising call (batch 1)", round(ddim_best / 10, 2), "ms", command,
           note="DDIM-10 chunk / 10; " + note)


if __name__ == "__main__":
    main()
