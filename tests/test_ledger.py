"""benchmarks/ledger.py: finished evaluations kept in the repository count on a machine whose cache is empty."""

from __future__ import annotations

import json

import benchmarks.bench_act_chunks as bac
import benchmarks.resumable as resumable
from benchmarks.ledger import main as keep
from benchmarks.resumable import evaluation_file, state_path
from coursekit.stats import wilson_interval


def _finished_run(root, bench, name, files: dict[str, str], unfinished=False):
    run = root / bench / name
    run.mkdir(parents=True)
    (run / "config.json").write_text("{}")
    for fname, text in files.items():
        (run / fname).write_text(text)
    if unfinished:
        state_path(run).write_text("resume state")
    return run


def test_a_kept_evaluation_is_read_before_the_caches(tmp_path):
    run = tmp_path / "cache" / "act_chunks" / "act-k-10_seed0_s7000"
    ledger = tmp_path / "ledger"
    assert evaluation_file(run, "eval_open_100000_50.json", ledger) == run / "eval_open_100000_50.json"
    kept = ledger / "act_chunks" / "act-k-10_seed0_s7000" / "eval_open_100000_50.json"
    kept.parent.mkdir(parents=True)
    kept.write_text("{}")
    assert evaluation_file(run, "eval_open_100000_50.json", ledger) == kept
    assert evaluation_file(run, "eval_te_100000_50.json", ledger) == run / "eval_te_100000_50.json"


def test_keep_copies_finished_runs_only_and_never_overwrites(tmp_path, capsys):
    cache, ledger = tmp_path / "cache", tmp_path / "ledger"
    _finished_run(cache, "act_chunks", "act-k-1_seed0_s7000", {"eval_open_100000_50.json": "[1]", "config.json": "{}"})
    _finished_run(cache, "act_chunks", "act-k-1_seed1_s7000", {"eval_open_100000_50.json": "[2]"}, unfinished=True)
    _finished_run(cache, "chunk_ablation", "dp_seed0_s6000_person", {"eval_100000_200.json": "[3]"})
    _finished_run(cache, "pixels", "dp_end-to-end", {"eval_100000_200.json": "[4]"})  # not a sweep's cache
    args = ["--cache", str(cache), "--ledger", str(ledger)]
    assert keep([*args, "--check"]) == 0 and not ledger.exists()
    assert keep(args) == 0
    kept = sorted(str(p.relative_to(ledger)) for p in ledger.rglob("*.json"))
    assert kept == ["act_chunks/act-k-1_seed0_s7000/eval_open_100000_50.json",
                    "chunk_ablation/dp_seed0_s6000_person/eval_100000_200.json"]
    assert keep(args) == 0 and "0 new" in capsys.readouterr().out  # nothing twice
    (cache / "act_chunks" / "act-k-1_seed0_s7000" / "eval_open_100000_50.json").write_text("[9]")
    assert keep(args) == 1  # a disagreeing cache copy is reported ...
    assert (ledger / kept[0]).read_text() == "[1]"  # ... and the kept file left as it was
    assert "differs from the cache" in capsys.readouterr().out


def test_rows_are_recorded_from_kept_evaluations_without_training(tmp_path, monkeypatch):
    import benchmarks.results

    ledger, out = tmp_path / "ledger", tmp_path / "act_chunks"
    strict = {0: [True, False, True, True], 1: [True, True, False, False]}
    for ts, outcomes in strict.items():
        for tag in ("open", "te"):
            kept = ledger / "act_chunks" / f"act-k-10_seed{ts}_s7000" / f"eval_{tag}_100000_4.json"
            kept.parent.mkdir(parents=True, exist_ok=True)
            kept.write_text(json.dumps({"seed": list(range(100000, 100004)), "strict": outcomes,
                                        "stage": [4 if s else 2 for s in outcomes], "seconds": 1.0}))
    monkeypatch.setattr(resumable, "LEDGER", ledger)

    def must_not_run(*a, **k):
        raise AssertionError("a run whose evaluations are kept was trained, loaded or its data collected")

    monkeypatch.setattr(bac, "train_or_load", must_not_run)
    monkeypatch.setattr(bac, "demonstrations", must_not_run)
    monkeypatch.setattr(bac, "BLOCK", 4)
    rows = []
    monkeypatch.setattr(benchmarks.results, "record", lambda *a, **k: rows.append((a, k)))
    bac.main(["--steps", "7000", "--train-seeds", "0", "1", "--episodes", "4", "--variants", "ACT k=10", "--out", str(out)])
    assert [a[1] for a, _ in rows] == [f"ACT k=10, {e}: strict success" for e in bac.EXECUTORS]
    (_, _, value, _, _), k = rows[0]
    assert value == 62.5 and k["n"] == 8  # 5 of 8 pooled over both training seeds
    assert k["interval"] == [round(100 * x, 1) for x in wilson_interval(5, 8)]
    assert "per seed: 75.0 %, 50.0 %" in k["note"]


def _sweep_rows():
    from coursekit.viz.measured import load_rows

    return sorted(load_rows(bac.SECTION).values(), key=lambda r: r["name"])


def test_every_recorded_k_sweep_row_is_what_its_kept_evaluations_say():
    """A row of the arm-pair sweep recomputed from the ledger: pooled strict success and n (rows recorded
    from a cache whose evaluations were never kept are allowed, but then all of their files are absent)."""
    import re

    from benchmarks.resumable import LEDGER

    for row in _sweep_rows():
        name, executor = row["name"].removesuffix(": strict success").rsplit(", ", 1)
        tag = "open" if executor == bac.EXECUTORS[0] else "te"
        steps = int(re.search(r"--steps (\d+)", row["command"]).group(1))
        task = re.search(r"--task (\w+)", row["command"])
        task = task.group(1) if task else bac.TASKS[0]
        name = name.removesuffix(bac.label("", task))  # "ACT k=1 on insertion" -> "ACT k=1"
        seeds = [int(s) for s in re.search(r"training seeds \[([\d, ]+)\]", row["note"]).group(1).split(", ")]
        runs = [bac.run_dir(LEDGER / "act_chunks", name, ts, steps, task) for ts in seeds]
        files = [sorted(run.glob(f"eval_{tag}_*.json")) for run in runs]
        if not any(files):  # the insertion's runs were all kept as they finished (long_runs queue c)
            assert task == bac.TASKS[0], f"{row['name']}: no kept evaluation under {runs[0]}"
            continue
        assert all(files), f"{row['name']}: some training seeds' evaluations are kept, not all: {runs}"
        strict = [s for fs in files for f in fs for s in json.loads(f.read_text())["strict"]]
        assert len(strict) == row["n"], row["name"]
        assert round(100 * sum(strict) / len(strict), 1) == row["value"], row["name"]
