"""The shipped checkpoints reproduce their golden episodes through `coursekit eval`, and each has its row.

``tests/golden/shipped_episodes.json`` holds, for every checkpoint in ``coursekit/checkpoints/``,
the outcome of each of 12 held-out episodes under the command a student uses (``coursekit eval
CKPT --episodes 12 --threads 1``: the checkpoint's own sampler and executor), with the weights'
sha256; ``python -m benchmarks.shipped_golden`` wrote it. Here the same command runs again and is
compared episode by episode, which catches a stale checkpoint, a changed sampler or executor, or a
changed environment even where a mean over 200 episodes would hide it. Evaluation is deterministic
by seed: on the machine fingerprint the golden file records (torch build, CPU) every episode must
match exactly; elsewhere a network's sums round differently and a contact-rich rollout can amplify
that into another outcome (on an AMD EPYC, against the Intel Xeon recording, 4 of the deterministic
regressor's 12 episodes ended differently, the other heads' at most 1), so up to half may differ
there: a changed sampler, executor or environment alters an episode from its first step on and
so changes nearly all twelve. The quality figures are the checkpoints' rows in
``benchmarks/results.json`` (more seeds, their own benchmarks); the first test ties each
checkpoint to its row. The reproductions are marked ``slow`` (``make test`` runs them, ``make
test-fast`` not): about a minute in all.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "coursekit" / "checkpoints"
RESULTS = json.loads((ROOT / "benchmarks" / "results.json").read_text())

# checkpoint -> its row in benchmarks/results.json (the README's results table)
CASES = [
    ("pusht_diffusion_state", "Diffusion Policy/shipped checkpoint score, DDIM-10 (notebook 05)"),
    ("pusht_regression_state", "Diffusion Policy/shipped regression checkpoint score (notebook 05)"),
    ("pusht_flow_state", "Flow matching/shipped flow checkpoint score, Euler-10 (notebook 10)"),
    ("act_transfer_cube", "ACT/ACT transfer cube strict success, shipped checkpoint, temporal ensembling m=0.01"),
    ("act_insertion", "ACT/ACT insertion strict success, shipped checkpoint, temporal ensembling m=0.01"),
    ("dp_transfer_cube", "ACT/DP transfer cube success (strict, DDIM-10, Ta=8)"),
    ("act_pusht", "ACT/ACT PushT score (mean of max coverage)"),
    ("pusht_diffusion_pixels", "Pixels (PushT): two-stage route/shipped pixel checkpoint score, DDIM-10 (notebook 12)"),
]


def test_every_shipped_checkpoint_has_a_results_row():
    shipped = sorted(p.name for p in SHIPPED.iterdir() if (p / "config.json").is_file())
    assert shipped == sorted(c[0] for c in CASES), "a shipped checkpoint without a reproduced README row (or vice versa)"
    for _, row in CASES:
        assert row in RESULTS, f"README results table lacks {row!r}: run its benchmark"


GOLDEN = json.loads((ROOT / "tests" / "golden" / "shipped_episodes.json").read_text())


def test_golden_episodes_are_of_the_shipped_weights():
    from benchmarks.shipped_golden import weights_sha256

    assert sorted(GOLDEN["checkpoints"]) == sorted(c[0] for c in CASES), "golden episodes for other checkpoints"
    for name, golden in GOLDEN["checkpoints"].items():
        assert weights_sha256(SHIPPED / name) == golden["weights_sha256"], (
            f"coursekit/checkpoints/{name} changed since its golden episodes were recorded: "
            "run `.venv/bin/python -m benchmarks.shipped_golden` (and its benchmark row)")


def _differing(got: dict, want: dict) -> list[str]:
    assert got["seed"] == want["seed"], f"evaluated seeds {got['seed']} instead of {want['seed']}"
    return [f"seed {seed}: score {a:.4f} vs {b:.4f}, success {sa} vs {sb}, {na} vs {nb} steps"
            for seed, a, b, sa, sb, na, nb in zip(got["seed"], got["score"], want["score"], got["success"],
                                                  want["success"], got["steps"], want["steps"])
            if abs(a - b) > 1e-6 or sa != sb or na != nb]


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_shipped_checkpoint_reproduces_its_golden_episodes(name, tmp_path):
    from benchmarks.shipped_golden import eval_episodes, fingerprint

    golden = GOLDEN["checkpoints"][name]
    summary = eval_episodes(SHIPPED / name, tmp_path)
    differ = _differing(summary["per_episode"], golden["per_episode"])
    allowed = 0 if fingerprint() == GOLDEN["fingerprint"] else len(golden["per_episode"]["seed"]) // 2
    assert len(differ) <= allowed, (f"{name}: {len(differ)} of {len(golden['per_episode']['seed'])} episodes differ "
                                    f"from the golden run (at most {allowed} here): {differ}")
