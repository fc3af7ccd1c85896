"""benchmarks/bench_rtc_regime.py: the s grid stays inside RTC's regime d <= s <= H - d."""

from __future__ import annotations

import pytest

from benchmarks.bench_rtc_regime import regime_grid


@pytest.mark.parametrize("d", range(1, 8))
def test_grid_is_inside_the_regime_and_spans_it(d):
    H = 15
    grid = regime_grid(d, H, points=4, own=8)
    assert grid == sorted(set(grid))
    assert all(d <= s <= H - d for s in grid), grid
    assert grid[0] == d and grid[-1] == H - d  # both ends of the regime are measured
    assert (8 in grid) == (d <= 8 <= H - d)  # the head's own Ta joins when it is allowed


def test_no_regime_when_the_delay_is_over_half_the_horizon():
    assert regime_grid(8, 15) == []  # 8 > 15 - 8: the shipped Tp = 16 heads cannot run RTC at d = 8
    assert regime_grid(8, 31) == [8, 13, 18, 23]  # a Tp = 32 head can


def test_usable_horizon_of_the_shipped_pusht_head():
    from coursekit.checkpoint import SHIPPED_DIR, load_checkpoint

    policy = load_checkpoint(SHIPPED_DIR / "pusht_diffusion_state", device="cpu")
    spec = policy.execution_spec()
    assert spec.usable_horizon == spec.horizon - spec.n_obs_steps + 1 == 15  # Tp = 16, To = 2


def test_rtc_minus_async_is_paired_by_seed_whatever_the_block_order(monkeypatch):
    import numpy as np

    import benchmarks.bench_rtc_regime as brr
    from coursekit.stats import bootstrap_interval

    rows = []
    monkeypatch.setattr(brr.results, "record", lambda *a, **k: rows.append((a, k)))
    rng = np.random.default_rng(0)
    r = {s: float(x) for s, x in zip(range(100000, 100200), rng.uniform(0, 1, 200))}
    a = {s: float(x) for s, x in zip(range(100000, 100200), rng.uniform(0, 1, 200))}
    blocks = lambda d, order: [{"seeds": list(range(b, b + 50)), "max_reward": [d[s] for s in range(b, b + 50)]}
                               for b in order]
    rtc = {"s": 4, "parts": blocks(r, (100000, 100050, 100100, 100150)), "cmd": "x --strategies rtc --d 4"}
    naive = {"s": 6, "parts": blocks(a, (100150, 100100, 100050, 100000)), "cmd": "x --strategies async --d 4"}
    brr.paired_difference("dp", 4, rtc, naive, no_record=False)
    (args, kw), = rows
    diffs = [r[s] - a[s] for s in sorted(r)]
    assert args[1] == "PushT DP DDIM-10, d=4, best s: rtc minus async score"
    assert args[2] == round(float(np.mean(diffs)), 3) and kw["n"] == 200 and kw["seeds"] == "100000-100199"
    assert kw["interval"] == tuple(round(x, 3) for x in bootstrap_interval(diffs))
    assert "s = 4" in kw["note"] and "s = 6" in kw["note"] and "--strategies rtc,async" in args[4]
