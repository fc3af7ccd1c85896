"""benchmarks/long_runs.py: the queues name real variants and heads, and only record steps write rows."""

from __future__ import annotations

import pytest

import benchmarks.long_runs as lr
from benchmarks.bench_chunk_ablation import VARIANTS
from benchmarks.bench_act_chunks import SWEEP
from benchmarks.bench_act_chunks import VARIANTS as ACT_VARIANTS


@pytest.mark.parametrize("queue", sorted(lr.QUEUES))
def test_train_steps_never_record_and_name_what_exists(queue):
    for kind, step in lr.QUEUES[queue]():
        cmd = lr.command(kind, step, no_record=False)
        if cmd is None:
            continue
        if kind == "train":
            assert cmd[-1] == "--no-record", cmd  # one seed of several: no row yet
        if kind == "record":
            assert "--no-record" not in cmd
        if "--variants" in step:
            rest = step[step.index("--variants") + 1:]
            names = rest[:next((i for i, a in enumerate(rest) if a.startswith("--")), len(rest))]
            known = ACT_VARIANTS if step[0] == "bench_act_chunks" else VARIANTS
            assert names and all(any(n in v for v in known) for n in names), names


def test_no_record_skips_the_record_steps_and_passes_the_flag_on():
    for queue in lr.QUEUES.values():
        for kind, step in queue():
            cmd = lr.command(kind, step, no_record=True)
            assert (cmd is None) if kind == "record" else (cmd is None or kind not in ("train", "rows")
                                                            or cmd[-1] == "--no-record")


def test_a_failing_step_stops_the_queue(monkeypatch):
    calls = []
    monkeypatch.setattr(lr.subprocess, "call", lambda cmd, cwd: calls.append(cmd) or 3)
    assert lr.main(["b", "--no-record"]) == 3
    assert len(calls) == 1 and calls[0][2] == "benchmarks.bench_act_chunks"


def test_every_train_step_is_followed_by_keeping_its_evaluations():
    for queue in lr.QUEUES.values():
        steps = queue()
        for (kind, _), (after, _) in zip(steps, steps[1:]):
            if kind == "train":
                assert after == "keep"


@pytest.mark.parametrize(("queue", "task"), [("b", None), ("c", "insertion")])
def test_the_k_sweep_runs_variant_by_variant_over_all_seeds(queue, task):
    steps = lr.QUEUES[queue]()
    trains = [step for kind, step in steps if kind == "train"]
    order = [(step[step.index("--variants") + 1], int(step[-1])) for step in trains]
    assert order == [(v, s) for v in SWEEP for s in lr.SEEDS]
    for kind, step in steps:  # every step of the queue trains, keeps or records runs on its task
        if step[0] == "bench_act_chunks":
            assert (step[step.index("--task") + 1] if "--task" in step else None) == task, step
