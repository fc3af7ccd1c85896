"""The long benchmarks still to run, as queues, one per core: run them in pieces, on any day, until they are done.

    .venv/bin/python -m benchmarks.long_runs a          # core 1: the three heads on person-like demonstrations
    .venv/bin/python -m benchmarks.long_runs b          # core 2: ACT's k sweep, then ACT from the camera
    .venv/bin/python -m benchmarks.long_runs c          # either core: the k sweep again on insertion
    .venv/bin/python -m benchmarks.long_runs a --list   # the queue, one command per line

Every step is a command of a resumable benchmark (``benchmarks/resumable.py``): a finished run is
loaded from ``~/.cache/coursekit`` and an unfinished one continues where it stopped, so stopping a
queue and starting it again costs at most a minute per core, and a queue run to the end twice
trains nothing the second time. A ``train`` step trains and evaluates one run (one variant, one
training seed) and writes no row: a row over fewer training seeds than its benchmark names would be
wrong in the table until the others are in. The ``keep`` step after it copies the run's evaluations
into the repository's ledger (``benchmarks/ledger.py``): commit them, and the run counts on the next
machine too, whose cache starts empty. The ``record`` step writes the rows from the ledger and the
cache in seconds, and a ``rows`` step is a benchmark whose one command is complete (ACT from the
camera, the end-to-end pixel run). ``--no-record`` (a queue run from a second working tree while the
first is being edited) skips the record steps and passes ``--no-record`` to the rows steps.

Done and recorded (their rows name their commands): the budget curve (2000, 6000, 20 000 steps),
RTC in its regime for both heads and the Tp = 32 flow head, stage 1 of the pixel route with and
without crops, the two-stage pixel policy (shipped) and the end-to-end one (``PIXEL_STEPS_END_TO_END``
says how its budget was set; its checkpoint is not kept, so it left the queue rather than be trained
again on a new machine). Queues a and b are kept in the ledger (ACT from the camera on training
seed 0 too): on any machine they record their rows without training. Queue c (issue 24's "and
insertion if the budget allows"; about four CPU-hours, like b's sweep) is the one still training.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.bench_act_chunks import SWEEP, TASKS, task_args
from benchmarks.resumable import cache_dir

PERSON = cache_dir("data") / "pusht_400ep_seed0_noise0-5_person.npz"
SEEDS = (0, 1, 2)
PIXEL_STEPS_END_TO_END = 16600
"""The end-to-end pixel run's steps at the two-stage route's CPU budget: stage 1 (3000 steps of 128
frames at 2249 images/s, 171 s: row "stage 1: training throughput") plus 19259 frozen-encoder steps
at 387 samples/s of batch 128 (6370 s), divided by an end-to-end step at 325 samples/s (0.394 s):
the idle throughput rows of ``bench_pixels`` and ``bench_pixel_policy`` (AMD EPYC, 2026-12-03).
Rendering the frames (about 20 s) is the same for both routes and not counted."""


def ablation(variants: list[str], steps: int, seeds, data: Path) -> list[str]:
    return ["bench_chunk_ablation", "--only", "train", "--steps", str(steps), "--train-seeds", *map(str, seeds),
            "--variants", *variants, "--threads", "1", "--data", str(data), "--name-budget"]


def act_variant(name: str, task: str = TASKS[0]) -> list[str]:
    return ["bench_act_chunks", *task_args(task), "--steps", "7000", "--threads", "1", "--variants", name]


def act_sweep(task: str) -> list[tuple[str, list[str]]]:
    """ACT's k sweep and no-CVAE run on ``task``: each run trained and kept, then each variant's rows."""
    steps: list[tuple[str, list[str]]] = []
    for variant in SWEEP:  # variant by variant, so that a cut queue leaves whole rows behind
        for s in SEEDS:
            steps += [("train", [*act_variant(variant, task), "--train-seeds", str(s)]), ("keep", ["ledger"])]
    return steps + [("record", [*act_variant(v, task), "--train-seeds", *map(str, SEEDS)]) for v in SWEEP]


def queue_a() -> list[tuple[str, list[str]]]:
    """Issue 24's PushT runs: the three heads on person-like demonstrations, step-matched."""
    person = ["Diffusion Policy", "chunked regression", "single-step"]
    steps: list[tuple[str, list[str]]] = [("data", ["collect", str(PERSON), "person"])]
    for variant in person:
        for s in SEEDS:
            steps += [("train", ablation([variant], 6000, [s], PERSON)), ("keep", ["ledger"])]
    steps += [("record", ablation(person, 6000, SEEDS, PERSON))]
    return steps


def queue_b() -> list[tuple[str, list[str]]]:
    """Issues 24 (item 3) and 26: ACT's k sweep and no-CVAE run on the transfer cube, then ACT from the camera."""
    return [*act_sweep(TASKS[0]),
            ("rows", [*act_variant("ACT k=100 from the top camera"), "--train-seeds", "0"])]  # 26's stretch


def queue_c() -> list[tuple[str, list[str]]]:
    """Issue 24 (item 3, "and insertion if the budget allows"): the same sweep on the insertion."""
    return act_sweep(TASKS[1])


QUEUES = {"a": queue_a, "b": queue_b, "c": queue_c}
SKIPPED = {"data": lambda step: f"{step[1]} exists",
           "record": lambda step: f"{step[0]}: recording skipped (--no-record)"}
"""Why a step of each kind that can be skipped was, for the log."""
ROOT = Path(__file__).resolve().parents[1]


def command(kind: str, args: list[str], no_record: bool) -> list[str] | None:
    """The argv of one step, or None when it has nothing to do (a data set made, a head trained)."""
    if kind == "data":
        out, style = Path(args[1]), args[2]
        if out.is_file():
            return None
        return ["coursekit", "collect", "pusht", "--episodes", "400", "--seed", "0", "--action-noise", "0,5",
                *(["--style", style] if style else []), "--out", str(out)]
    if kind == "keep":
        return [sys.executable, "-m", "benchmarks.ledger"]
    if kind == "record" and no_record:
        return None
    tail = ["--no-record"] if kind == "train" or (no_record and kind == "rows") else []
    return [sys.executable, "-m", f"benchmarks.{args[0]}", *args[1:], *tail]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("queue", choices=sorted(QUEUES), help="a: person-like PushT runs; b: ACT's k sweep, then the camera; c: the sweep on insertion")
    parser.add_argument("--list", action="store_true", help="print the queue's commands and stop")
    parser.add_argument("--no-record", action="store_true", help="write no rows (record steps are skipped)")
    args = parser.parse_args(argv)
    steps = QUEUES[args.queue]()
    for i, (kind, step) in enumerate(steps, 1):
        cmd = command(kind, step, args.no_record)
        line = f"[{args.queue} {i}/{len(steps)}] {shlex.join(cmd) if cmd else SKIPPED[kind](step)}"
        print(line, flush=True)
        if cmd is None or args.list:
            continue
        if cmd[0] == "coursekit":
            cmd = [str(Path(sys.executable).with_name("coursekit")), *cmd[1:]]
        start = time.perf_counter()
        rc = subprocess.call(cmd, cwd=ROOT)
        print(f"[{args.queue} {i}/{len(steps)}] exit {rc} after {time.perf_counter() - start:.0f} s", flush=True)
        if rc != 0:
            return rc
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
