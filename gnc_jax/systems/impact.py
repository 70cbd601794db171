"""Statistics of the systems that end in an impact on a small body (the impactor and the
intercept): B-plane miss statistics, the hit probability on the target's silhouette, their
paper labels and the smooth tuning objective."""

from typing import Any

import jax.numpy as jnp
import numpy as np

from ..params import param
from ..statistics import std, wilson_interval


def impact_statistics(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    miss = o["miss_m"][ok]
    dv = o["dv_mps"][ok]
    firings = o["firings"][ok]
    if miss.size == 0:
        return {}
    counts = np.bincount(firings)
    return dict(
        miss_rms_m=float(np.sqrt(np.mean(miss**2))),
        miss_mean_m=float(np.mean(miss)),
        miss_max_m=float(np.max(miss)),
        miss_p99_m=float(np.percentile(miss, 99)),
        miss_t_mean_m=float(np.mean(o["miss_t_m"][ok])),
        miss_r_mean_m=float(np.mean(o["miss_r_m"][ok])),
        dv_mean_mps=float(np.mean(dv)),
        dv_std_mps=std(dv),
        dv_max_mps=float(np.max(dv)),
        firings_mean=float(np.mean(firings)),
        firings_max=int(np.max(firings)),
        firings_mode=int(np.argmax(counts)),
        firings_histogram={int(k): int(v) for k, v in enumerate(counts) if v},
        fuel_mean_kg=float(np.mean(o["fuel_kg"][ok])),
    )


def miss_limit_param():
    """The ``guidance.miss_limit_km`` field of a B-plane system (the impactor, the intercept):
    its delivery tolerance, in metres once read."""
    return param(
        10.0,
        toml="miss_limit_km",
        section="guidance",
        scale=1e3,
        lo=0.0,
        lo_open=True,
        hi=1e7,
        units="km",
        doc=(
            "delivery tolerance: a run whose B-plane point lies farther than this from the aim "
            "point (an intercept's: the target's centre) reads missed and is left out of the "
            "statistics. The default lies well outside a guided run's scatter (the packaged "
            "studies' largest miss is about 0.3 km), so that it flags a run that failed (an "
            "engine too weak to steer, a trigger that never fires: misses of 10 to 1000 km) "
            "without truncating the statistics; a target whose silhouette reaches beyond it "
            "needs a larger one"
        ),
    )


HIT_RULE = (
    "hit: the B-plane impact point inside the target's silhouette along S (the shadow of the "
    "target as the scenario defines it: the [target] ellipsoid, or the sphere of "
    "dynamics.target_radius_m of an intercept), widened by gravitational focusing; ok runs, "
    "95 % Wilson interval"
)


def hit_statistics(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    """Probability of hitting the body (:mod:`gnc_jax.geometry.silhouette`) over the ``ok``
    runs, with its 95 % Wilson score interval (:func:`gnc_jax.statistics.wilson_interval`);
    when runs failed, also over every run (``*_all_runs``), a failed run counted by where it
    crossed the B-plane (a run that crossed nowhere, NaN, as a miss)."""
    n = int(np.sum(ok))
    if n == 0:
        return {}
    hits = int(np.sum(o["silhouette_ratio"][ok] < 1.0))
    lo, hi = wilson_interval(hits, n)
    out = dict(
        hits=hits,
        hit_probability=hits / n,
        hit_probability_ci95=[lo, hi],
        hit_rule=HIT_RULE,
    )
    if n < ok.size:  # runs failed: the probability over every run, each where it crossed
        # the B-plane (a failed run is not a hit unless it crossed inside; NaN is a miss)
        every = int(np.sum(np.nan_to_num(o["silhouette_ratio"], nan=np.inf) < 1.0))
        lo_all, hi_all = wilson_interval(every, ok.size)
        out.update(
            hits_all_runs=every,
            hit_probability_all_runs=every / ok.size,
            hit_probability_all_runs_ci95=[lo_all, hi_all],
        )
    return out


IMPACT_LABELS = {
    "miss_rms_m": "miss RMS (m)",
    "miss_max_m": "miss max (m)",
    "miss_mean_m": "miss mean (m)",
    "dv_mean_mps": "Δv mean (m/s)",
    "dv_max_mps": "Δv max (m/s)",
    "firings_max": "firings max",
    "firings_mode": "firings mode",
    "firings_mean": "firings (mean)",
}


def impact_objective(outcomes):
    """Miss (softened at 1 m) plus 10 s x Δv, averaged over the runs: differentiable."""
    return jnp.mean(jnp.sqrt(outcomes.miss_m**2 + 1.0)) + 10.0 * jnp.mean(outcomes.dv_mps)


IMPACT_BUDGET_METRICS = {
    "miss_m": lambda o: o["miss_m"],
    "miss_t_m": lambda o: o["miss_t_m"],
    "miss_r_m": lambda o: o["miss_r_m"],
    "dv_mps": lambda o: o["dv_mps"],
    "firings": lambda o: 1.0 * o["firings"],
    "hit": lambda o: 1.0 * (o["silhouette_ratio"] < 1.0),  # as hit_statistics
}
"""What the error budget of an impact decomposes: the miss, its B-plane components, Δv,
firings and the hit indicator (whose mean is the hit probability)."""
