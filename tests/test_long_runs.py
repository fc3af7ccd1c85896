"""benchmarks/long_runs.py: the queues name real variants and heads, and only record steps write rows."""

from __future__ import annotations

import pytest

import benchmarks.long_runs as lr
from benchmarks.bench_chunk_ablation import VARIANTS
from benchmarks.bench_latency import HEADS as LATENCY_HEADS


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
            names = step[step.index("--variants") + 1:step.index("--threads")]
            assert all(any(n in v for v in VARIANTS) for n in names), names
        if "--heads" in step:
            assert all(h in LATENCY_HEADS for h in step[step.index("--heads") + 1].split(","))


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
    assert len(calls) == 1 and calls[0][2] == "benchmarks.bench_rtc_regime"
