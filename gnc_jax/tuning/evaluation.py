"""Evaluation with the hard logic: the objective of given gains on given runs, and the
paired held-out comparison of initial and tuned gains with its bootstrap interval."""

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..scenario import Scenario, load_scenario
from .objectives import TERMS, _term_label, parse_objective
from .parametrisation import resolve_gains, with_schedule_starts
from .problem import TuningProblem, heldout_indices


def _hard_scored(problem, gains, indices) -> tuple[float, int]:
    """``(objective, failed runs)`` of the hard logic with ``gains`` on runs ``indices``."""
    idx, valid = problem.padded(indices)
    fn = problem.jitted("hard", lambda: problem.hard)
    value, out = fn(problem.args, jnp.asarray(gains), idx, valid)
    return float(value), int(round(float(problem.failed(out, valid))))


def ranking_key(value: float, failed: int) -> tuple[int, float]:
    """The order of gains evaluated on the same runs: fewer failed runs first, then the lower
    objective (an objective with no ok run, non-finite, last). A gain that turns runs into
    failures can lower an objective taken over the ``ok`` runs; it never ranks better."""
    return failed, (value if np.isfinite(value) else np.inf)


def lexicographic_scores(values, failed):
    """Scores of a population on common runs that order it as :func:`ranking_key` does: each
    member's objective plus, per failed run beyond the population's fewest, the spread of the
    finite objectives plus one; a member with a non-finite objective (no ok run) scores that
    spread above the worst finite score. A population whose members all fail as many runs,
    each with a finite objective, scores its objectives unchanged; one without a finite
    objective keeps its values. The ES's estimate, which weighs score differences, then takes
    a failure as a step of the spread rather than losing the generation to a NaN."""
    values, failed = np.asarray(values, dtype=float), np.asarray(failed, dtype=float)
    finite = np.isfinite(values)
    if not finite.any():
        return values
    extra = failed - failed[finite].min()
    spread = float(np.ptp(values[finite])) + 1.0
    scores = values + extra * spread
    return np.where(finite, scores, np.max(scores[finite]) + spread)


def hard_scores(
    scenario, params, objective, gains, runs: int, seed: int = 0
) -> list[tuple[float, int]]:
    """``(objective, failed runs)`` of each gain vector of ``gains`` (file units) on the same
    ``runs`` held-out runs: a grid check, a sweep or a baseline on the runs :func:`tune` holds
    out. Rank them with :func:`ranking_key` (``min(scores, key=lambda s: ranking_key(*s))``):
    the built-in terms are taken over the ``ok`` runs, so the objective alone can prefer a gain
    that fails more runs."""
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    scenario = with_schedule_starts(scenario, params)
    resolved = resolve_gains(scenario, params)
    problem = TuningProblem(scenario, resolved, parse_objective(objective, scenario), seed)
    return [_hard_scored(problem, g, heldout_indices(runs)) for g in gains]


def hard_objectives(scenario, params, objective, gains, runs: int, seed: int = 0) -> list[float]:
    """The hard objective of each gain vector of ``gains`` as :func:`hard_scores` evaluates
    it, without the failed runs (to rank gains, use :func:`hard_scores`)."""
    return [value for value, _ in hard_scores(scenario, params, objective, gains, runs, seed)]


def paired_interval(stat_a, stat_b, n, confidence=0.95, resamples=1000, seed=0):
    """``(difference, lo, hi)`` of ``stat_b - stat_a`` over ``n`` paired runs: the difference on
    all runs and its percentile-bootstrap confidence interval, each resample drawing the same
    runs for both sides (``stat_x(indices)`` evaluates a statistic on a subset of the runs)."""
    rng = np.random.default_rng(seed)
    # One resample's indices at a time (n of them, not resamples x n): the same draws as one
    # (resamples, n) array, row by row.
    diffs = []
    for _ in range(resamples):
        d = rng.integers(0, n, size=n)
        diffs.append(stat_b(d) - stat_a(d))
    diffs = np.array(diffs)
    q = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(diffs, [q, 1.0 - q])
    every = np.arange(n)
    return float(stat_b(every) - stat_a(every)), float(lo), float(hi)


def evaluate_heldout(
    problem: TuningProblem,
    initial,
    tuned,
    runs: int,
    chunk: int | None = None,
    confidence: float = 0.95,
) -> dict[str, Any]:
    """Initial vs tuned gains (file units) on the same ``runs`` held-out runs, hard logic.

    Rows: the objective and each of its terms, with the paired difference (tuned - initial)
    and its bootstrap confidence interval over the runs that end ``ok`` with both gains. An
    objective with the ``failed`` term resamples every held-out run instead: that term counts
    each side's failed runs among them, the others stay over the runs ``ok`` with both. A user
    objective that takes ``runs`` resamples every held-out run too, each side's weights its
    own ``ok`` runs (the objective of :func:`hard_scores` on all of them).
    """
    indices = heldout_indices(runs)
    chunk = min(chunk or (problem.system.chunk_per_device or 512) * problem.n_dev, runs)
    sides = {}
    for side, gains in (("initial", initial), ("tuned", tuned)):
        parts = []
        for start in range(0, runs, chunk):
            real = indices[start : start + chunk]
            idx, _ = problem.padded(real, size=chunk)  # one compiled shape
            out = problem.hard_outcomes(np.asarray(gains), idx)
            n = len(real)
            parts.append(jax.tree_util.tree_map(lambda x, n=n: np.asarray(x)[:n], out))
        sides[side] = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)
    w = {s: np.asarray(problem.weights(o, jnp.ones(runs))) for s, o in sides.items()}
    paired = (w["initial"] > 0) & (w["tuned"] > 0)
    both = np.flatnonzero(paired)
    objective = problem.objective
    # A user objective that takes the runs mask prices failed runs itself: it sees every
    # held-out run with its side's own ok runs as weights, as the tuner and hard_scores call it.
    own = objective.takes_runs
    over_every_run = own or any(not TERMS[name].over_ok for _, name, _ in objective.terms)
    resampled = np.arange(runs) if over_every_run else both
    # the runs the terms over ok runs are taken over: those ok with both gains
    counts = {s: ((w[s] > 0) if own else paired)[resampled].astype(float) for s in sides}

    def statistic(side, name):
        drawn = jax.tree_util.tree_map(lambda x: x[resampled], sides[side])

        def stat(i):
            sub = jax.tree_util.tree_map(lambda x: x[i], drawn)
            if name == "objective":
                return float(objective.value(sub, jnp.asarray(counts[side][i]), None))
            return objective.term_values(sub, jnp.asarray(counts[side][i]))[name]

        return stat

    names = ["objective"]
    if objective.fn is None and len(objective.terms) > 1:
        names += [_term_label(n, arg) for _, n, arg in objective.terms]
    rows = []
    for name in names:
        a, b = statistic("initial", name), statistic("tuned", name)
        every = np.arange(len(resampled))
        ini, tun = a(every), b(every)
        diff, lo, hi = paired_interval(a, b, len(resampled), confidence)
        rows.append(
            dict(
                metric=name,
                initial=ini,
                tuned=tun,
                difference=diff,
                ci_low=lo,
                ci_high=hi,
                relative=diff / abs(ini) if ini else float("nan"),
            )
        )
    return dict(
        runs=runs,
        paired_runs=len(both),
        failed={s: int(runs - (w[s] > 0).sum()) for s in sides},
        confidence=confidence,
        first_index=int(indices[0]),
        rows=rows,
        outcomes=sides,
    )


def heldout_table(heldout: dict) -> str:
    """The held-out table as text."""
    pct = round(100 * heldout["confidence"])
    lines = [
        f"held-out: {heldout['paired_runs']} paired runs (indices from {heldout['first_index']}),"
        f" hard logic; failed initial {heldout['failed']['initial']}, tuned "
        f"{heldout['failed']['tuned']}",
        f"  {'metric':<22} {'initial':>12} {'tuned':>12} {'tuned-initial':>14} "
        f"{f'{pct} % CI':>26} {'change':>8}",
    ]
    for r in heldout["rows"]:
        ci = f"[{r['ci_low']:.4g}, {r['ci_high']:.4g}]"
        lines.append(
            f"  {r['metric']:<22} {r['initial']:>12.5g} {r['tuned']:>12.5g} "
            f"{r['difference']:>14.4g} {ci:>26} "
            f"{100 * r['relative']:>7.2f}%"
        )
    return "\n".join(lines)
