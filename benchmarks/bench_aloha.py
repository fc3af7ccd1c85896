"""ALOHA arm pair: physics speed, camera frame time, scripted-expert success, demo generation time.

Run: ``.venv/bin/python -m benchmarks.bench_aloha`` (about 5 minutes on 2 free cores).
Options: ``--only speed|success|generation`` (``--skip-success`` = ``--only speed``), ``--seeds N``
(success-rate seeds per task, default 200 from ``--first-seed`` 100000: the protocol range),
``--no-record`` (print only).

- Real-time factor: simulated seconds / wall seconds of ``env.step`` with state observations,
  replaying a scripted demonstration (so contacts and grasps are in the mix).
- Frame time: one 240x320 "top" camera image (``env.render_camera``), median of 50.
- Scripted success over the protocol seeds (the policies' held-out spawns): the replayed
  demonstration judged STRICTLY on its final state, the published lenient stage-4 success, and
  the end-effector (mocap) rollout's strict success before replay; each rate with its Wilson
  95 % interval (:func:`coursekit.stats.rate_estimate`), ``n`` and ``seeds``.
- Generation time: ``coursekit collect aloha-cube|aloha-insertion`` for 50 demonstrations
  (the collect function itself, failures and retries included; no file writing).
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np

from benchmarks.results import record
from coursekit.envs.aloha import AlohaEnv
from coursekit.stats import Estimate, rate_estimate
from coursekit.experts.aloha_scripted import collect, scripted_episode
from coursekit.experts.aloha_waypoints import EndEffectorScene

COMMAND = ".venv/bin/python -m benchmarks.bench_aloha"
SECTION = "ALOHA"
TASK_LABEL = {"transfer_cube": "transfer cube", "insertion": "insertion"}
PARTS = ("speed", "success", "generation")
"""speed: physics real-time factor and camera frame; success: scripted success rates; generation: 50 demos' wall time."""


def real_time_factor(task: str, repeats: int = 3) -> tuple[float, float]:
    """Best-of-``repeats`` simulated time / (wall time, process CPU time) of a 400-step replayed
    demonstration with state observations. On a shared machine the CPU-time figure is what the
    code costs; the wall-clock one is what you get under the current load."""
    env = AlohaEnv(task)
    episode, _ = scripted_episode(task, 0, env=env)
    best_wall = best_cpu = 0.0
    simulated = len(episode["action"]) * 0.02
    for _ in range(repeats):
        env.reset(options={"env_state": episode["env_state"][0]})
        t0, c0 = time.perf_counter(), time.process_time()
        for action in episode["action"]:
            env.step(action)
        best_wall = max(best_wall, simulated / (time.perf_counter() - t0))
        best_cpu = max(best_cpu, simulated / (time.process_time() - c0))
    return best_wall, best_cpu


def frame_ms(height: int = 240, width: int = 320, n: int = 50) -> tuple[float, float]:
    """Median (wall, CPU) milliseconds for one (height, width) top-camera image of a mid-episode state."""
    env = AlohaEnv("transfer_cube")
    episode, _ = scripted_episode("transfer_cube", 0, env=env)
    env.set_physics_state(episode["physics_qpos"][200])
    env.render_camera("top", (height, width))  # warm-up: context and buffers
    times, cpu = [], []
    for _ in range(n):
        t0, c0 = time.perf_counter(), time.process_time()
        env.render_camera("top", (height, width))
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    env.close()
    return float(np.median(times) * 1e3), float(np.median(cpu) * 1e3)


def success_rates(task: str, seeds: list[int]) -> dict[str, Estimate | list[int]]:
    """Strict (replay), lenient (replay) and strict (end-effector rollout) rates over ``seeds``, each
    with its Wilson interval, and the seeds whose replay failed the strict check."""
    env, scene = AlohaEnv(task), EndEffectorScene(task)
    strict, lenient, ee_strict = [], [], []
    for seed in seeds:
        episode, ee = scripted_episode(task, seed, env=env, scene=scene)
        strict.append(bool(episode["strict_success"]))
        lenient.append(bool(episode["lenient_success"]))
        ee_strict.append(bool(ee["strict_success"]))
    return {"strict": rate_estimate(np.asarray(strict)), "lenient": rate_estimate(np.asarray(lenient)),
            "ee_strict": rate_estimate(np.asarray(ee_strict)), "failed": [s for s, ok in zip(seeds, strict) if not ok]}


def generation_seconds(task: str, n_episodes: int = 50) -> tuple[float, float]:
    """(wall, CPU) seconds to collect ``n_episodes`` strictly successful demonstrations."""
    def cpu() -> float:  # this process + its finished worker processes
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + kids.ru_utime + kids.ru_stime

    t0, c0 = time.perf_counter(), cpu()
    collect(task, n_episodes, seed=0, progress=False)
    return time.perf_counter() - t0, cpu() - c0


def part_speed(put) -> None:
    """Physics real-time factor per task and the camera frame time (wall clock: load-dependent)."""
    load = f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    for task in ("transfer_cube", "insertion"):
        wall, cpu = real_time_factor(task)
        print(f"{task}: physics {wall:.0f}x real time (wall clock), {cpu:.0f}x per CPU second (state obs)")
        put(SECTION, f"physics real-time factor, {TASK_LABEL[task]}", round(wall, 1), "x", COMMAND, target=">= 20",
            note=f"env.step, state obs, replaying a scripted demo (50 Hz, 10 substeps); best of 3 wall clock; "
                 f"{cpu:.0f}x per CPU second; {load}")
    ms, cpu_ms = frame_ms()
    print(f"240x320 top camera frame: {ms:.1f} ms wall clock, {cpu_ms:.1f} ms CPU")
    put(SECTION, "240x320 camera frame", round(ms, 1), "ms", COMMAND, target="< 15",
        note=f"MUJOCO_GL=egl on the CPU (llvmpipe), shadows/reflections off; median of 50 wall clock; "
             f"{cpu_ms:.1f} ms CPU time; {load}")


def _put_rate(put, name: str, est: Estimate, cmd: str, seeds: str, note: str, target: str = "") -> None:
    """A scripted success rate in percent, with its Wilson interval, n and seed range."""
    put(SECTION, name, round(100 * est.value, 1), "%", cmd, target=target, note=f"Wilson 95 % interval; {note}",
        interval=(round(100 * est.lo, 1), round(100 * est.hi, 1)), n=est.n, seeds=seeds)


def part_success(put, n_seeds: int, first_seed: int) -> None:
    """Scripted strict / lenient / end-effector success on seeds first_seed.. (the protocol range by default)."""
    seeds = list(range(first_seed, first_seed + n_seeds))
    span = f"{seeds[0]}-{seeds[-1]}"
    cmd = f"{COMMAND} --only success --seeds {n_seeds} --first-seed {first_seed}"
    for task in ("transfer_cube", "insertion"):
        target = ">= 98 %" if task == "transfer_cube" else ">= 90 %"
        rates = success_rates(task, seeds)
        print(f"{task}: strict {rates['strict']}, lenient {rates['lenient']}, end-effector strict {rates['ee_strict']}; "
              f"failed seeds {rates['failed']}")
        label = TASK_LABEL[task]
        _put_rate(put, f"scripted strict success, {label}", rates["strict"], cmd, span,
                  f"spawn seeds {span}; final-state check after joint-space replay", target)
        _put_rate(put, f"scripted lenient (published stage 4) success, {label}", rates["lenient"], cmd, span,
                  f"spawn seeds {span}; stage 4 reached at any step of the replay")
        _put_rate(put, f"scripted strict success before replay (mocap), {label}", rates["ee_strict"], cmd, span,
                  f"spawn seeds {span}; final-state check in the end-effector scene")


def part_generation(put) -> None:
    """Wall time of collecting 50 demonstrations per task (load-dependent)."""
    for task in ("transfer_cube", "insertion"):
        seconds, cpu = generation_seconds(task)
        print(f"{task}: 50 demonstrations in {seconds:.1f} s wall clock, {cpu:.1f} s CPU")
        put(SECTION, f"50 demos generation time, {TASK_LABEL[task]}", round(seconds, 1), "s", COMMAND, target="< 30",
            note=f"coursekit collect aloha-cube|aloha-insertion without file writing (2 worker processes); {cpu:.1f} s CPU "
                 f"time; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=PARTS, default=list(PARTS), help="parts to run (default all)")
    parser.add_argument("--seeds", type=int, default=200, help="seeds per task for the success rates (protocol: 200)")
    parser.add_argument("--first-seed", type=int, default=100_000, help="first spawn seed of the success rates "
                                                                          "(protocol: 100000; demonstrations use 0..)")
    parser.add_argument("--skip-success", action="store_true", help="= --only speed")
    parser.add_argument("--no-record", action="store_true", help="print only; do not write results.json")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.first_seed < 0:
        parser.error(f"need --seeds >= 1 and --first-seed >= 0, got --seeds {args.seeds} --first-seed {args.first_seed}")
    parts = ["speed"] if args.skip_success else args.only
    put = (lambda *a, **k: None) if args.no_record else record
    if "speed" in parts:
        part_speed(put)
    if "success" in parts:
        part_success(put, args.seeds, args.first_seed)
    if "generation" in parts:
        part_generation(put)

if __name__ == "__main__":
    main()
