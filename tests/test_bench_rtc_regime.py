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
