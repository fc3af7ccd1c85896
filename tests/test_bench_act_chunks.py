"""benchmarks/bench_act_chunks.py: the k sweep's rows (pooled strict success, Wilson interval) and its cache."""

from __future__ import annotations

import pytest

import benchmarks.bench_act_chunks as bac
from coursekit.stats import wilson_interval


def test_variants_are_the_issues_k_grid_and_the_cvae_ablation():
    sweep = [bac.VARIANTS[name] for name in bac.SWEEP]
    assert [v["chunk_size"] for v in sweep] == [1, 10, 25, 100, 100]
    assert [v.get("use_vae", True) for v in sweep] == [True] * 4 + [False]
    assert all("features" not in v for v in sweep)  # the sweep is on states; the camera run is asked for by name
    (camera,) = set(bac.VARIANTS) - set(bac.SWEEP)
    assert bac.VARIANTS[camera]["features"] == "aloha_image" and bac.VARIANTS[camera]["chunk_size"] == 100


def test_the_transfer_cube_keeps_its_names_and_the_insertion_is_named_everywhere(tmp_path):
    assert bac.TASKS[0] == "transfer_cube"  # the default: its runs are in the ledger under these names
    assert bac.run_dir(tmp_path, "ACT k=10", 1, 7000) == tmp_path / "act-k-10_seed1_s7000"
    assert bac.run_dir(tmp_path, "ACT k=10", 1, 7000, "insertion") == tmp_path / "act-k-10_insertion_seed1_s7000"
    assert bac.label("ACT k=100 without CVAE", "transfer_cube") == "ACT k=100 without CVAE"
    assert bac.label("ACT k=100 without CVAE", "insertion") == "ACT k=100 without CVAE on insertion"


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("task", ["transfer_cube", "insertion"])
def test_a_tiny_sweep_records_wilson_rows_and_reuses_its_cache(tmp_path, monkeypatch, task):
    import benchmarks.results

    rows = []
    monkeypatch.setattr(bac, "N_DEMOS", 2)
    monkeypatch.setattr(bac, "EPISODE_STEPS", 40)  # the loop and its cache, not the task: 40 of 400 steps
    monkeypatch.setattr(benchmarks.results, "record", lambda *a, **k: rows.append((a, k)))
    argv = ["--steps", "2", "--train-seeds", "0", "--episodes", "1", "--variants", "ACT k=10", "--out", str(tmp_path),
            "--task", task]
    bac.main(argv)
    names = [a[1] for a, _ in rows]
    assert names == [f"{bac.label('ACT k=10', task)}, {e}: strict success" for e in bac.EXECUTORS]
    assert list(tmp_path.glob("aloha_*.npz")) == [tmp_path / f"aloha_{task}_2ep_seed0.npz"]
    for (_, _, value, unit, cmd), k in rows:
        successes = round(value / 100 * k["n"])
        assert unit == "%" and k["n"] == 1 and k["seeds"] == "100000-100000"
        assert k["interval"] == [round(100 * x, 1) for x in wilson_interval(successes, k["n"])]
        assert "--variants 'ACT k=10'" in cmd and "--steps 2" in cmd
        assert ("--task insertion" in cmd) == (task == "insertion") and task.replace("_", " ") in k["note"]
    evals = sorted(bac.run_dir(tmp_path, "ACT k=10", 0, 2, task).glob("eval_*.json"))
    assert [p.name for p in evals] == ["eval_open_100000_1.json", "eval_te_100000_1.json"]
    stamps = [p.stat().st_mtime_ns for p in evals]
    rows.clear()
    bac.main(argv)  # everything cached: same rows, nothing re-evaluated
    assert [a[1] for a, _ in rows] == names and [p.stat().st_mtime_ns for p in evals] == stamps
    assert not list(tmp_path.glob(".*.state.pt")), "the resume state outlived its run"
