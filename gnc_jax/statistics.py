"""Statistics of study outcomes shared by the systems: spreads, binomial proportions.

A spread (standard deviation, 3σ interval, central interval) needs two runs: from one ``ok``
run it is ``None`` (JSON null), not 0, which would read as a study without dispersion.

The Wilson score interval (Wilson 1927) of a proportion k / n at confidence 1 - alpha:

    centre = (p + z^2 / 2n) / (1 + z^2 / n),
    half width = z / (1 + z^2 / n) sqrt(p (1 - p) / n + z^2 / 4n^2),

with p = k / n and z the standard normal's 1 - alpha/2 quantile (1.959964 at 95 %). Unlike the
normal (Wald) interval it stays inside [0, 1] and does not collapse to a point at k = 0 or
k = n, which is where a hit probability lives.
"""

import math
from statistics import NormalDist

import numpy as np

MIN_SPREAD_RUNS = 2
"""Fewest runs a spread is computed from; below it the spread is ``None``."""


def std(x) -> float | None:
    """The standard deviation of ``x`` (population form, as ``np.std``), ``None`` below
    :data:`MIN_SPREAD_RUNS` values."""
    x = np.asarray(x)
    return float(np.std(x)) if x.size >= MIN_SPREAD_RUNS else None


def spread(fn, x):
    """``fn(x)`` (a spread of the values ``x``), ``None`` below :data:`MIN_SPREAD_RUNS`."""
    return fn(x) if np.asarray(x).size >= MIN_SPREAD_RUNS else None


def wilson_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval ``(lo, hi)`` of the proportion ``k / n`` (``n >= 1``)."""
    if n < 1 or not 0 <= k <= n:
        raise ValueError(f"wilson_interval: k = {k}, n = {n}; allowed: 0 <= k <= n, n >= 1")
    z = NormalDist().inv_cdf(0.5 + 0.5 * confidence)
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n))
    # exact end points at k = 0 and k = n (the formula gives them up to rounding)
    lo = 0.0 if k == 0 else max(centre - half, 0.0)
    hi = 1.0 if k == n else min(centre + half, 1.0)
    return lo, hi


def interval_text(interval, unit: str = "") -> str:
    """An interval ``(lo, hi)`` as ``[lo, hi] unit``, both ends to the decimals that give its
    width three significant digits (4 significant digits each where it has no finite width);
    ``n/a`` for ``None`` (a spread from fewer than :data:`MIN_SPREAD_RUNS` runs)."""
    if interval is None:
        return "n/a"
    lo, hi = (float(x) for x in interval)
    width = abs(hi - lo)
    if math.isfinite(width) and width > 0:
        decimals = max(0, 2 - math.floor(math.log10(width)))
        text = f"[{lo:.{decimals}f}, {hi:.{decimals}f}]"
    else:
        text = f"[{lo:.4g}, {hi:.4g}]"
    return f"{text} {unit}" if unit else text


__all__ = ["MIN_SPREAD_RUNS", "interval_text", "spread", "std", "wilson_interval"]
