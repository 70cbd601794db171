"""PNG reports of a study directory written by ``gnc-jax run`` (``gnc-jax report DIR``).

The figures are the study's system's (:meth:`gnc_jax.systems.AbstractSystem.figures`); the runs
they draw (:meth:`~gnc_jax.systems.AbstractSystem.figure_traces`) are simulated here, so the
systems never call the Monte Carlo layer.
"""

import pathlib

from .budget.figures import BUDGET_JSON, budget_figures
from .montecarlo import simulate_one, simulate_traces
from .results import ResultsError, load_results


def figure_traces(system, summary: dict, runs: dict, scenario) -> dict:
    """``{name: (outcomes, traces)}`` of the runs ``system``'s figures ask for (its
    :meth:`~gnc_jax.systems.AbstractSystem.figure_traces`), on the study's keys."""
    out = {}
    for name, request in system.figure_traces(summary, runs, scenario).items():
        sc = scenario.with_overrides(request.overrides) if request.overrides else scenario
        seed = summary.get("seed") if request.seed is None else request.seed
        if request.single:
            out[name] = simulate_one(sc, index=request.indices[0], seed=seed)
        else:
            out[name] = simulate_traces(sc, list(request.indices), seed=seed, every=request.every)
    return out


def report(run_dir, out_dir=None) -> list[str]:
    """Write the PNG figures of a study directory; returns their paths.

    Args:
        run_dir: a directory written by ``gnc-jax run`` / :meth:`Study.save`, or by
            ``gnc-jax budget`` / :meth:`Budget.save` (a bar chart per metric).
        out_dir: where to write the PNGs (default: ``run_dir``).
    """
    if (pathlib.Path(run_dir) / BUDGET_JSON).is_file():
        return [str(p) for p in budget_figures(run_dir, out_dir)]
    summary, runs, scenario = load_results(run_dir)
    out = pathlib.Path(out_dir or run_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ResultsError(f"{out}: cannot create ({e.strerror or e})") from None
    system = scenario.system
    try:
        traces = figure_traces(system, summary, runs, scenario)
        return [str(p) for p in system.figures(summary, runs, scenario, out, traces)]
    except KeyError as e:
        raise ResultsError(
            f"{pathlib.Path(run_dir)}: runs.parquet or summary.json lacks {e} (written by "
            "another gnc_jax version or edited?)"
        ) from None
    except PermissionError as e:
        raise ResultsError(f"{e.filename}: cannot write ({e.strerror})") from None
