"""PushT environment speed: env steps per second for state and pixel observations (one core).

Run: ``.venv/bin/python -m benchmarks.bench_pusht_env``. Actions aim near the block so that
contacts (the expensive part of the physics) happen in a realistic share of steps.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.results import record
from coursekit.envs.pusht import PushTEnv

COMMAND = ".venv/bin/python -m benchmarks.bench_pusht_env"
SECTION = "PushT env"


def steps_per_second(obs_type: str, n_steps: int, seed: int = 0) -> float:
    """Env steps/s of ``PushTEnv(obs_type)`` under block-seeking random targets (resets included)."""
    env = PushTEnv(obs_type=obs_type)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    t0 = time.perf_counter()
    for i in range(n_steps):
        block_xy = env.block_pose()[:2]
        _, _, terminated, truncated, _ = env.step(block_xy + rng.normal(0.0, 40.0, size=2))
        if terminated or truncated:
            env.reset(seed=seed + i + 1)
    return n_steps / (time.perf_counter() - t0)


def lookahead_microseconds(n: int = 2000) -> float:
    """Cost of one planner look-ahead step: ``set_state`` + ``physics_step`` (microseconds)."""
    env = PushTEnv()
    env.reset(seed=0)
    state = env.get_state()
    t0 = time.perf_counter()
    for _ in range(n):
        env.set_state(state)
        env.physics_step(state[2:4])
    return (time.perf_counter() - t0) / n * 1e6


def main() -> None:
    best = lambda f, *a: max(f(*a) for _ in range(3))  # noqa: E731  (best of 3: shared machine)
    state = best(steps_per_second, "state", 5000)
    record(SECTION, "env steps/s (state obs)", round(state), "steps/s", COMMAND, target=">= 5000",
           note="one core, best of 3 runs of 5000 steps, block-seeking random targets")
    keypoints = best(steps_per_second, "keypoints", 3000)
    record(SECTION, "env steps/s (keypoints obs)", round(keypoints), "steps/s", COMMAND)
    pixels = best(steps_per_second, "pixels", 2000)
    record(SECTION, "env steps/s (96x96 pixels obs)", round(pixels), "steps/s", COMMAND, target=">= 1000",
           note="one core, PIL rasteriser at 4x supersampling")
    look = min(lookahead_microseconds() for _ in range(3))
    record(SECTION, "set_state + physics_step", round(look, 1), "us", COMMAND,
           note="planner look-ahead primitive (10 substeps, no reward/obs)")
    for name, v in [("state", state), ("keypoints", keypoints), ("pixels", pixels)]:
        print(f"{name:10s} {v:10.0f} steps/s")
    print(f"look-ahead {look:10.1f} us/step")


if __name__ == "__main__":
    main()
