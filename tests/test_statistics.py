"""Binomial intervals against scipy (an established implementation)."""

import numpy as np
import pytest
from scipy import stats

from gnc_jax.statistics import wilson_interval


@pytest.mark.parametrize("n", [1, 7, 40, 300, 2000])
def test_wilson_interval_matches_scipy(n):
    for k in sorted({0, 1, n // 3, n // 2, n - 1, n}):
        ref = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
        np.testing.assert_allclose(wilson_interval(k, n), (ref.low, ref.high), atol=1e-12)


def test_wilson_interval_covers_at_its_level():
    """Coverage by brute force: over many binomial samples at p = 0.3, n = 200, the 95 %
    interval holds p in 95 +- 1.5 % of them (Wilson's coverage is close to nominal there)."""
    rng = np.random.default_rng(0)
    n, p = 200, 0.3
    ks = rng.binomial(n, p, size=4000)
    cover = np.mean([lo <= p <= hi for lo, hi in (wilson_interval(int(k), n) for k in ks)])
    assert abs(cover - 0.95) < 0.015


def test_wilson_interval_refuses_bad_counts():
    with pytest.raises(ValueError, match="0 <= k <= n"):
        wilson_interval(5, 3)
