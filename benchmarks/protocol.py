"""The evaluation protocol's command-line arguments, shared by the claims benchmarks.

A reported score is on >= 200 held-out reset seeds from 100000 (the protocol range); variants are
chosen on 200000+ (validation), never on the reported range. ``add_protocol_args`` adds
``--episodes``, ``--seed-start``, ``--threads`` and ``--no-record``; ``protocol_seeds`` checks
them, sets torch's threads and returns the seed list. ``t_estimate`` is the interval over
training seeds (a handful of means, so Student's t, not a bootstrap).
"""

from __future__ import annotations

import argparse

import numpy as np

PROTOCOL_START, VALIDATION_START = 100_000, 200_000


def add_protocol_args(parser: argparse.ArgumentParser, episodes: int = 200, what: str = "per policy") -> None:
    parser.add_argument("--episodes", type=int, default=episodes, help=f"held-out reset seeds {what} (protocol: 200)")
    parser.add_argument("--seed-start", type=int, default=PROTOCOL_START,
                        help=f"first reset seed (protocol {PROTOCOL_START}, validation {VALIDATION_START})")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--no-record", action="store_true", help="print only, do not write results.json")


def protocol_seeds(args: argparse.Namespace) -> list[int]:
    """Check ``--episodes`` / ``--seed-start`` / ``--threads`` (SystemExit naming the bad value), set
    torch's threads, and return the reset seeds [seed_start, seed_start + episodes)."""
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    if args.threads < 1:
        raise SystemExit(f"--threads must be >= 1, got {args.threads}")
    if args.seed_start < 0:
        raise SystemExit(f"--seed-start must be >= 0, got {args.seed_start}")
    if not PROTOCOL_START <= args.seed_start < VALIDATION_START:
        print(f"note: seeds from {args.seed_start} are not the reported range ({PROTOCOL_START}+); "
              f"{VALIDATION_START}+ is validation")
    import torch

    torch.set_num_threads(args.threads)
    return list(range(args.seed_start, args.seed_start + args.episodes))


def t_estimate(values: list[float]) -> tuple[float, float, float]:
    """(mean, lo, hi): 95 % t-interval over training seeds (lo = hi = mean for one seed)."""
    from scipy import stats as sps

    k, mean = len(values), float(np.mean(values))
    if k < 2:
        return mean, mean, mean
    half = float(sps.t.ppf(0.975, k - 1) * np.std(values, ddof=1) / np.sqrt(k))
    return mean, mean - half, mean + half
