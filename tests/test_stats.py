"""Intervals against trusted references: scipy's Wilson interval and the normal approximation."""

import numpy as np
import pytest
from scipy import stats as sps

from coursekit.stats import bootstrap_interval, mean_estimate, rate_estimate, wilson_interval


@pytest.mark.parametrize("k,n", [(0, 10), (3, 10), (10, 10), (95, 200), (179, 200), (1, 50)])
def test_wilson_matches_scipy(k, n):
    ref = sps.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(ref.low, abs=1e-12) and hi == pytest.approx(ref.high, abs=1e-12)


def test_bootstrap_close_to_normal_interval_and_deterministic():
    x = np.random.default_rng(1).uniform(0, 1, size=400)
    lo, hi = bootstrap_interval(x)
    se = x.std(ddof=1) / np.sqrt(x.size)
    assert lo == pytest.approx(x.mean() - 1.96 * se, abs=0.01)
    assert hi == pytest.approx(x.mean() + 1.96 * se, abs=0.01)
    assert bootstrap_interval(x) == (lo, hi)


def test_estimates_and_bad_input():
    e = rate_estimate(np.array([True] * 150 + [False] * 50))
    assert e.value == 0.75 and e.n == 200 and e.lo < 0.75 < e.hi
    m = mean_estimate([0.5] * 10)
    assert (m.value, m.lo, m.hi) == (0.5, 0.5, 0.5)
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(11, 10)
    with pytest.raises(ValueError, match="finite"):
        bootstrap_interval([0.1, float("nan")])
    with pytest.raises(ValueError, match="boolean"):
        rate_estimate([1, 0])
