"""``gnc_jax.budget``: a variance-based error budget of a scenario, per error source, three
ways, each on the study engine (:func:`gnc_jax.run_study`, with the sources' draws routed).

* **pick-freeze** (Sobol indices): the study's runs (seed ``s``, design A), the runs of a
  second seed (B) and, per factor ``f``, the runs that take ``f``'s draws from B and every
  other factor's from A (AB_f); nothing else changes, so the truth and every model the
  filter and the law hold are the study's;
* **one at a time**: per factor, the study's runs with only that factor's draws on (the
  others' draws zero, their magnitudes -- what the filter believes -- untouched), beside
  all-on (the study itself) and all-off (the nominal run);
* **linear**: :mod:`.linear`.

Runs: ``N (2 + factors)`` for pick-freeze, ``N factors`` for one at a time, and ``N`` forward-
mode runs with one tangent per factor for the linear method.
"""

import sys
import time

import numpy as np
from tqdm.auto import tqdm

from ..montecarlo import ANNOUNCE_S, MAX_HOURS, build, estimate_cost
from ..scenario import Scenario, ScenarioError
from ..study import check_seed, run_study
from ..systems.base import get_system
from . import estimators
from .linear import linear_responses
from .plan import factors, layout, plan
from .result import Budget

METHODS = ("sobol", "oat", "linear")
SEED_B_OFFSET = 0x9E3779B9
"""The paired sample's root seed is ``(seed + SEED_B_OFFSET) mod 2^32``."""
BOOTSTRAP = 400
LINEAR_COST = 3.0
"""A forward-mode run with one tangent per factor costs about this many runs per factor."""


def _check(scenario, system, runs, metrics, methods):
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < estimators.MIN_RUNS:
        raise ScenarioError(f"runs: {runs!r}; allowed: an integer >= {estimators.MIN_RUNS}")
    known = tuple(system.budget_metrics)
    if not known:
        raise ScenarioError(f"scenario.kind: {system.name} declares no budget metrics")
    metrics = known if metrics is None else tuple(metrics)
    for m in metrics:
        if m not in known:
            raise ScenarioError(f"metrics: {m!r}; allowed: {', '.join(known)}")
    for m in methods:
        if m not in METHODS:
            raise ScenarioError(f"methods: {m!r}; allowed: {', '.join(METHODS)}")
    return metrics


def budget_cost(scenario: Scenario, runs: int, n_factors: int, methods=METHODS):
    """``(study runs, run-equivalents, CostEstimate)`` of a budget."""
    study_runs = runs * (
        (2 + n_factors if "sobol" in methods else 1) + (n_factors if "oat" in methods else 0)
    )
    equivalent = study_runs + (LINEAR_COST * n_factors * runs if "linear" in methods else 0)
    return study_runs, equivalent, estimate_cost(scenario, int(np.ceil(equivalent)))


def budget(
    scenario: Scenario,
    runs: int = 200,
    seed: int | None = None,
    metrics=None,
    groups=None,
    methods=METHODS,
    max_hours: float = MAX_HOURS,
    progress: bool | None = None,
    bootstrap: int = BOOTSTRAP,
    level: float = estimators.LEVEL,
    chunk_size: int | None = None,
    n_devices: int | None = None,
) -> Budget:
    """The error budget of ``scenario`` (see the module docstring).

    Args:
        scenario: a loaded scenario whose system declares ``error_sources``.
        runs: ``N``, runs per design (the cost is announced on stderr above 30 s and refused
            above ``max_hours``, before anything compiles).
        seed: the study's root seed (default: the scenario's); the all-on design is the
            study of this seed, run for run.
        metrics: names of the system's ``budget_metrics`` (default: all).
        groups: ``True`` to take the system's ``source_groups`` as single factors, or
            ``{group: (source, ...)}``; ``None``: every source alone.
        methods: a subset of ``("sobol", "oat", "linear")``.
        bootstrap, level: resamples and confidence level of the intervals.
        chunk_size, n_devices: as :func:`~gnc_jax.run_study`'s, for every design (and the
            linear pass's chunk); no index depends on them, run for run.
    """
    system = get_system(scenario.kind)
    seed = check_seed(scenario.seed if seed is None else seed)
    metrics = _check(scenario, system, runs, metrics, tuple(methods))
    facs, inactive = factors(system, scenario, groups)
    names, n = list(facs), len(facs)
    # a reason the system declares why derivatives are no sensitivities: the linear method is
    # reported as not available, and neither run nor costed
    declared = system.linear_unavailable(scenario.config) if "linear" in methods else None
    run_methods = tuple(m for m in methods if not (m == "linear" and declared))
    study_runs, _, cost = budget_cost(scenario, runs, n, run_methods)
    if cost.seconds is not None and cost.seconds > max_hours * 3600:
        raise ScenarioError(
            f"cost: {cost}; allowed: at most {max_hours:g} h (raise max_hours, CLI --max-hours, "
            "or use fewer runs)"
        )
    announce = cost.seconds is not None and cost.seconds > ANNOUNCE_S and progress is not False
    if announce:
        print(f"{scenario.name}: budget of {n} factors, estimated {cost}", file=sys.stderr)
    lay = layout(system, facs)
    seed_b = (seed + SEED_B_OFFSET) % 2**32
    bar = tqdm(
        total=study_runs + (runs if "linear" in run_methods else 0),
        desc=scenario.name,
        unit="run",
        disable=not (progress or announce),
    )
    t0 = time.perf_counter()
    compile_s = 0.0

    def design(from_b=(), on=None):
        nonlocal compile_s
        st = run_study(
            scenario,
            runs,
            seed,
            progress=False,
            max_hours=max_hours,
            chunk_size=chunk_size,
            n_devices=n_devices,
            draws=plan(seed, seed_b, n, lay, from_b, on),
        )
        compile_s += st.compile_s
        bar.update(runs)
        o = st.outcomes
        values = np.stack([np.asarray(system.budget_metrics[m](o), float) for m in metrics])
        return values, st.ok & np.isfinite(values).all(axis=0)

    try:
        f_a, ok_a = design()
        designs = {"all_on": (f_a, ok_a)}
        if "sobol" in methods:
            designs["b"] = design(from_b=range(n + 1))
            for i in range(n):
                designs[f"ab:{names[i]}"] = design(from_b=[i])
        if "oat" in methods:
            for i in range(n):
                designs[f"oat:{names[i]}"] = design(on=[i])
        linear = None
        if "linear" in methods:
            sim, law = build(scenario)
            t_lin = time.perf_counter()
            linear = declared
            if linear is None:
                try:
                    linear = linear_responses(
                        system, sim, law, seed, runs, metrics, n, lay, chunk_size or 64, bar.update
                    )
                except Exception as e:  # a construct forward mode cannot differentiate
                    linear = f"{type(e).__name__}: {str(e).splitlines()[0][:200]}"
            linear_s = time.perf_counter() - t_lin
    finally:
        bar.close()
    wall_s = time.perf_counter() - t0
    nominal = _nominal(system, scenario, runs, metrics, n, lay, seed, (chunk_size, n_devices))
    rows = _analyse(designs, linear, names, metrics, runs, (bootstrap, seed, level))
    if isinstance(linear, tuple):
        for i, name in enumerate(names):
            designs[f"linear:{name}"] = (linear[0][:, i, :], linear[1])
    return Budget(
        scenario=scenario,
        runs=runs,
        seed=seed,
        metrics=list(metrics),
        factors=facs,
        inactive=inactive,
        methods=list(methods),
        rows=rows["rows"],
        checks=rows["checks"],
        counts=rows["counts"],
        nominal=nominal,
        wall_s=wall_s,
        compile_s=compile_s,
        linear_s=linear_s if "linear" in methods else None,
        linear_error=linear if isinstance(linear, str) else None,
        samples=designs,
    )


def _nominal(system, scenario, runs, metrics, n, lay, seed, engine) -> dict:
    """The all-off run: every draw zero. Run as a design of ``runs`` runs (the program the
    other designs compiled), which must all be the same run."""
    chunk_size, n_devices = engine
    st = run_study(
        scenario,
        runs,
        seed,
        chunk_size,
        False,
        n_devices,
        draws=plan(seed, seed, n, lay, on=()),
    )
    o = st.outcomes
    values = {m: np.asarray(system.budget_metrics[m](o), float) for m in metrics}
    same = all(np.array_equal(v, np.full_like(v, v[0]), equal_nan=True) for v in values.values())
    out = {m: float(v[0]) for m, v in values.items()}
    return dict(status=int(st.status[0]), identical_runs=bool(same), **out)


def _analyse(designs, linear, names, metrics, runs, boot) -> dict:
    """The rows of the budget table (one per metric, factor and method) and the checks."""
    rows, checks = [], {}
    f_a, ok_a = designs["all_on"]
    sobol_ok = ok_a.copy()
    if "b" in designs:
        sobol_ok &= designs["b"][1]
        for name in names:
            sobol_ok &= designs[f"ab:{name}"][1]
    oat_ok = ok_a.copy()
    for name in names:
        if f"oat:{name}" in designs:
            oat_ok &= designs[f"oat:{name}"][1]
    counts = dict(
        runs=runs, all_on_ok=int(ok_a.sum()), sobol_ok=int(sobol_ok.sum()), oat_ok=int(oat_ok.sum())
    )
    lin_ok = None
    if isinstance(linear, tuple):
        lin_ok = ok_a & linear[1] & np.isfinite(linear[0]).all(axis=(0, 1))
        counts["linear_ok"] = int(lin_ok.sum())
    for j, metric in enumerate(metrics):
        rows += _rows_of(metric, j, designs, linear, names, sobol_ok, oat_ok, lin_ok, boot, checks)
    return dict(rows=rows, checks=checks, counts=counts)


def _rows_of(metric, j, designs, linear, names, sobol_ok, oat_ok, lin_ok, boot, checks):
    rows = []
    bootstrap, seed, level = boot
    f_a = designs["all_on"][0][j]

    def add(method, i, share, lo, hi, variance):
        rows.append(
            dict(
                metric=metric,
                source=names[i],
                method=method,
                share=float(share),
                share_lo=float(lo),
                share_hi=float(hi),
                variance=float(variance),
            )
        )

    if "b" in designs and sobol_ok.sum() >= estimators.MIN_RUNS:
        m = sobol_ok
        f_ab = np.stack([designs[f"ab:{s}"][0][j][m] for s in names])
        rows_boot = estimators.resamples(int(m.sum()), bootstrap, seed)
        s = estimators.sobol(f_a[m], designs["b"][0][j][m], f_ab, rows_boot, level)
        for i in range(len(names)):
            add(
                "first_order",
                i,
                s["first"][i],
                s["first_lo"][i],
                s["first_hi"][i],
                s["first"][i] * s["variance"],
            )
            add(
                "total",
                i,
                s["total"][i],
                s["total_lo"][i],
                s["total_hi"][i],
                s["total"][i] * s["variance"],
            )
        checks[metric] = dict(
            variance=s["variance"],
            first_sum=s["first_sum"],
            first_sum_lo=s["first_sum_lo"],
            first_sum_hi=s["first_sum_hi"],
            interaction=s["interaction"],
            interaction_lo=s["interaction_lo"],
            interaction_hi=s["interaction_hi"],
            first_sum_le_1=bool(s["first_sum_lo"] <= 1.0),
            total_ge_first=bool(np.all(s["total_hi"] >= s["first_lo"])),
        )
    if any(k.startswith("oat:") for k in designs) and oat_ok.sum() >= estimators.MIN_RUNS:
        m = oat_ok
        parts = np.stack([designs[f"oat:{s}"][0][j][m] for s in names])
        rows_boot = estimators.resamples(int(m.sum()), bootstrap, seed + 1)
        r = estimators.variance_shares(parts, f_a[m], rows_boot, level=level)
        for i in range(len(names)):
            add(
                "one_at_a_time",
                i,
                r["share"][i],
                r["share_lo"][i],
                r["share_hi"][i],
                r["variance"][i],
            )
        checks.setdefault(metric, {})["all_on_variance"] = float(f_a[m].var(ddof=1))
        checks[metric]["oat_sum"] = float(np.sum(r["share"]))
    if lin_ok is not None and lin_ok.sum() >= estimators.MIN_RUNS:
        m = lin_ok
        rows_boot = estimators.resamples(int(m.sum()), bootstrap, seed + 2)
        r = estimators.variance_shares(
            linear[0][j][:, m], f_a[m], rows_boot, centred=False, level=level
        )
        for i in range(len(names)):
            add("linear", i, r["share"][i], r["share_lo"][i], r["share_hi"][i], r["variance"][i])
        checks.setdefault(metric, {})["linear_sum"] = float(np.sum(r["share"]))
    return rows


__all__ = ["METHODS", "budget", "budget_cost"]
