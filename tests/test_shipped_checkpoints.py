"""The shipped checkpoints reproduce the README's results table through `coursekit eval`.

Each row below was written by a benchmark (``benchmarks/results.json``) from the very files in
``coursekit/checkpoints/``; here the same evaluation runs through the command line a student
uses (50 held-out episodes, the checkpoint's own sampler/executor, one torch thread). The
evaluation is deterministic by seed, but a different CPU (or thread count) rounds the network's
sums differently and a contact-rich rollout can amplify that, so the comparison allows a small
tolerance: a few episodes' worth, far below the gap a wrong or stale checkpoint would show.
Each reproduction takes minutes: they are marked ``slow`` (``make test`` runs them, ``make test-fast`` not).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from coursekit.cli import main as cli_main

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "coursekit" / "checkpoints"
RESULTS = json.loads((ROOT / "benchmarks" / "results.json").read_text())

# (checkpoint, results.json row, summary key, scale to the row's unit, tolerance in the row's unit)
CASES = [
    ("pusht_diffusion_state", "Diffusion Policy/shipped checkpoint score, DDIM-10 (notebook 05)", "score", 1.0, 0.05),
    ("pusht_regression_state", "Diffusion Policy/shipped regression checkpoint score (notebook 05)", "score", 1.0, 0.05),
    ("pusht_flow_state", "Flow matching/shipped flow checkpoint score, Euler-10 (notebook 10)", "score", 1.0, 0.05),
    ("act_transfer_cube", "ACT/ACT transfer cube strict success, shipped checkpoint, temporal ensembling m=0.01",
     "strict_success_rate", 100.0, 6.0),
    ("act_insertion", "ACT/ACT insertion strict success, shipped checkpoint, temporal ensembling m=0.01",
     "strict_success_rate", 100.0, 6.0),
    ("dp_transfer_cube", "ACT/DP transfer cube success (strict, DDIM-10, Ta=8)", "strict_success_rate", 100.0, 6.0),
    ("act_pusht", "ACT/ACT PushT score (mean of max coverage)", "score", 1.0, 0.05),
]


def test_every_shipped_checkpoint_has_a_results_row():
    shipped = sorted(p.name for p in SHIPPED.iterdir() if (p / "config.json").is_file())
    assert shipped == sorted(c[0] for c in CASES), "a shipped checkpoint without a reproduced README row (or vice versa)"
    for _, row, *_ in CASES:
        assert row in RESULTS, f"README results table lacks {row!r}: run its benchmark"


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("name,row,key,scale,tol", CASES, ids=[c[0] for c in CASES])
def test_shipped_checkpoint_reproduces_readme_row(name, row, key, scale, tol, tmp_path, capsys):
    import torch

    out = tmp_path / "eval.json"
    threads = torch.get_num_threads()
    try:
        rc = cli_main(["eval", str(SHIPPED / name), "--episodes", "50", "--threads", "1", "--no-progress", "--json", str(out)])
    finally:
        torch.set_num_threads(threads)  # --threads sets it process-wide
    assert rc == 0
    summary = json.loads(out.read_text())
    got = scale * summary[key]
    want = RESULTS[row]["value"]
    assert abs(got - want) <= tol, f"{name}: `coursekit eval` gives {got:.3f}, README says {want} ({row})"
