"""Operating envelopes: a grid of Monte Carlo studies over scenario fields.

``envelope(scenario, grid, runs)`` runs one vmapped study (:func:`gnc_jax.run_study`) per cell
of the grid, the product of the values of each ``section.field`` axis, and writes

* ``cells.parquet``: one row per cell (the grid values, ``status``, the metrics, the
  system's pre-check columns, runs, failures, wall time);
* one heat-map PNG per metric (one axis: a line plot), with infeasible and refused cells
  marked and the system's overlay (the capsule: its entry corridor and reachable footprint).

Before anything is simulated, the system's :meth:`~gnc_jax.systems.AbstractSystem.envelope_check`
marks cells that cannot work whatever the guidance (the capsule: outside the entry corridor);
they are not simulated. A cell whose scenario the system refuses while it is built (e.g. a
capsule target the reference design cannot reach) is recorded as ``refused`` with the reason.
Every cell's values are validated before the first study: a bad grid stops at once with one
line naming the field, and so does a field given on two axes. So does an envelope whose cost
estimate exceeds ``max_hours``: the cells' :func:`~gnc_jax.estimate_cost` (every cell's,
infeasible ones included, or on a grid of more than ``COST_SAMPLE`` cells their mean over that
many cells spread over the grid, times the cells) plus ``CELL_OVERHEAD_S`` per cell, refused
before the cells are validated; an estimate above ``ANNOUNCE_S`` is printed. A grid of more
than ``MAX_CELLS`` cells, or an axis of more values, is refused when its specs are read.
"""

import dataclasses
import itertools
import json
import math
import pathlib
import sys
import time
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .backend import select
from .cells import run_cells
from .montecarlo import ANNOUNCE_S, MAX_HOURS
from .planner import duration_text, estimate_cost
from .scenario import Scenario, ScenarioError
from .study import check_seed, run_study

SIMULATED, INFEASIBLE, REFUSED = "simulated", "infeasible", "refused"
CELL_OVERHEAD_S = 0.07
"""Wall seconds an envelope spends on a cell besides its runs (validating the cell's scenario,
building its simulation, starting its study, summarising it), added to the runs' estimate.
Measured: ``deep-impact-los`` (its test overrides), 20 cells of 2 runs on the 2-core machine,
0.074 s per cell after the first, of which the runs' estimate is 0.002 s."""
COST_SAMPLE = 256
"""Cells costed, at most: a larger grid's runs are estimated from this many of its cells."""
MAX_CELLS = int(MAX_HOURS * 3600 / CELL_OVERHEAD_S)
"""Cells of a grid, and values of an axis, at most (1,234,285): the cells whose
``CELL_OVERHEAD_S`` alone fills the default ``MAX_HOURS``. Checked when the axes are read,
before their values are made, whatever ``max_hours``: a larger sweep is several envelopes."""


def parse_grid(spec: str) -> tuple[str, list[float]]:
    """``"section.field=a:b:n"`` (n evenly spaced values from a to b) or
    ``"section.field=v1,v2,..."`` -> ``(field, values)``."""
    key, sep, text = spec.partition("=")
    key = key.strip()
    if not sep or key.count(".") not in (1, 2):
        raise ScenarioError(
            f"--grid {spec}: expected section.field=a:b:n; allowed: e.g. entry.fpa_deg=-6.5:-5.5:5"
        )
    try:
        if ":" in text:
            a, b, n = text.split(":")
            n_val = int(n)
            if n_val < 1:
                raise ValueError
            a_val, b_val = float(a), float(b)
        else:
            values = [float(x) for x in text.split(",")]
    except ValueError:
        raise ScenarioError(
            f"--grid {spec}: {text!r} is not a:b:n or a list of numbers; allowed: two numbers "
            "and a whole number of values n >= 1 (e.g. -6.5:-5.5:5), or v1,v2,..."
        ) from None
    if ":" in text:
        if n_val > MAX_CELLS:
            raise ScenarioError(
                f"--grid {spec}: {n_val} values; allowed: at most {MAX_CELLS} values on an axis "
                f"and cells on the grid (their {CELL_OVERHEAD_S:g} s per cell alone take "
                f"{MAX_HOURS:g} h; split the sweep)"
            )
        values = np.linspace(a_val, b_val, n_val).tolist()
    if not all(math.isfinite(v) for v in values):
        raise ScenarioError(f"--grid {spec}: values must be finite numbers")
    if ":" in text and len(values) == 1 and float(a) != float(b):
        raise ScenarioError(
            f"--grid {spec}: one value cannot span {a} .. {b}; allowed: n >= 2, or the single "
            f"value alone (--grid {key}={a})"
        )
    return key, [round(v, 12) for v in values]


@dataclasses.dataclass
class Envelope:
    """An envelope's cells (one dict per cell, the rows of ``cells.parquet``), its axes and
    the metrics its heat maps show (``{summary key: label}``)."""

    scenario: Scenario
    axes: dict[str, list[float]]
    cells: list[dict[str, Any]]
    metrics: dict[str, str]
    runs: int
    seed: int

    def table(self) -> pa.Table:
        keys = list(dict.fromkeys(k for c in self.cells for k in c))
        cols = {}
        for k in keys:
            vals = [c.get(k) for c in self.cells]
            if all(v is None or isinstance(v, (int, float, bool, np.number)) for v in vals):
                cols[k] = pa.array([np.nan if v is None else float(v) for v in vals])
            else:
                cols[k] = pa.array(["" if v is None else str(v) for v in vals])
        return pa.table(cols)

    def save(self, out_dir) -> list[pathlib.Path]:
        """``cells.parquet``, ``envelope.json`` (axes, metrics, settings) and the heat maps."""
        out = pathlib.Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        pq.write_table(self.table(), out / "cells.parquet")
        meta = dict(
            scenario=self.scenario.name,
            kind=self.scenario.kind,
            runs=self.runs,
            seed=self.seed,
            axes=self.axes,
            metrics=self.metrics,
        )
        (out / "envelope.json").write_text(json.dumps(meta, indent=2) + "\n")
        from .plotting import envelope_figures  # matplotlib only when writing figures

        return [out / "cells.parquet", out / "envelope.json", *envelope_figures(self, out)]


def grid_axes(grid) -> dict[str, list[float]]:
    """The axes ``{section.field: values}`` of ``grid`` (a mapping, or specs for
    :func:`parse_grid`); a field given twice is refused."""
    if isinstance(grid, dict):
        for key, values in grid.items():
            if (
                isinstance(values, (str, bytes))
                or not hasattr(values, "__len__")
                or not len(values)
            ):
                raise ScenarioError(
                    f"grid: {key} = {values!r}; allowed: a non-empty list of the field's values"
                )
        return _checked_size({key: list(values) for key, values in grid.items()}, "grid")
    if isinstance(grid, str):
        raise ScenarioError(
            f"grid: the single string {grid!r}; allowed: a list of section.field=a:b:n specs "
            "or a mapping {section.field: values}"
        )
    axes: dict[str, list[float]] = {}
    for spec in grid:
        key, values = parse_grid(spec)
        if key in axes:
            raise ScenarioError(
                f"--grid {spec}: {key} is already an axis; allowed: each field on one --grid "
                "(its values as a:b:n or v1,v2,...)"
            )
        axes[key] = values
    return _checked_size(axes, "--grid")


def _checked_size(axes: dict[str, list[float]], where: str) -> dict[str, list[float]]:
    """``axes``, refused (:class:`ScenarioError`) when the grid has more than ``MAX_CELLS``
    cells."""
    n_cells = math.prod(len(v) for v in axes.values())
    if n_cells > MAX_CELLS:
        sizes = " x ".join(f"{key} {len(v)}" for key, v in axes.items())
        raise ScenarioError(
            f"{where}: {sizes} = {n_cells} cells; allowed: at most {MAX_CELLS} cells (their "
            f"{CELL_OVERHEAD_S:g} s per cell alone take {MAX_HOURS:g} h; split the sweep)"
        )
    return axes


def _refuse_cost(what: str, max_hours: float) -> ScenarioError:
    return ScenarioError(
        f"cost: {what}; allowed: at most {max_hours:g} h (raise max_hours, CLI --max-hours, or "
        "use fewer cells or runs)"
    )


def _checked_cost(scenario, axes, runs, backend, max_hours, progress) -> None:
    """Refuse (:class:`ScenarioError`) an envelope estimated to take more than ``max_hours``
    (module docstring); announce one estimated to take more than ``ANNOUNCE_S``. A grid of
    more than ``COST_SAMPLE`` cells is costed from that many cells spread evenly over it (the
    mean of their runs' estimates, times the cells), before the others are validated."""
    names, values = list(axes), list(axes.values())
    n_cells = math.prod(len(v) for v in values)
    limit, overhead = max_hours * 3600, n_cells * CELL_OVERHEAD_S
    besides = f"{CELL_OVERHEAD_S:g} s per cell besides its runs"
    if overhead > limit:  # refused before any cell is built
        raise _refuse_cost(
            f"{n_cells} cells, more than {duration_text(overhead)} at {besides}", max_hours
        )
    picks = np.unique(np.linspace(0, n_cells - 1, min(n_cells, COST_SAMPLE)).round().astype(int))
    costs = []
    for flat in picks:
        index = np.unravel_index(flat, [len(v) for v in values])
        cell = scenario.with_overrides({k: v[i] for k, v, i in zip(names, values, index)})
        costs.append(estimate_cost(cell, runs, device=backend).seconds)
    known = [c for c in costs if c is not None]
    runs_s = float(np.mean(known)) * n_cells if known else 0.0
    sampled = f" estimated from {len(picks)} of the cells" if len(picks) < n_cells else ""
    what = (
        f"{n_cells} cells of {runs} runs, about {duration_text(runs_s + overhead)} "
        f"({duration_text(runs_s)} of runs{sampled}, and {besides})"
        + ("" if len(known) == len(costs) else "; some cells of unknown cost")
    )
    if runs_s + overhead > limit:
        raise _refuse_cost(what, max_hours)
    if runs_s + overhead > ANNOUNCE_S:
        _say(progress, f"envelope: estimated {what}")


def _cell_scenarios(scenario: Scenario, axes: dict[str, list[float]]):
    names = list(axes)
    for values in itertools.product(*axes.values()):
        point = dict(zip(names, values))
        yield point, scenario.with_overrides(point)  # validated: bad values stop here


def envelope(
    scenario: Scenario,
    grid,
    runs: int = 200,
    seed: int | None = None,
    out=None,
    progress: bool = True,
    client=None,
    device: str | None = None,
    batch_cells: bool | None = None,
    max_hours: float = MAX_HOURS,
) -> Envelope:
    """A grid of Monte Carlo studies of ``scenario`` (see the module docstring).

    Args:
        grid: ``{"section.field": values}`` or specs ``["section.field=a:b:n", ...]``.
        runs, seed: per cell (every cell uses the same per-run keys, so cells differ by their
            grid values, not by their draws).
        out: directory for ``cells.parquet``, ``envelope.json`` and the PNGs (optional).
        progress: one line per cell on stderr.
        client: a ``dask.distributed.Client``: each cell's chunks run on its workers (the path
            of :func:`gnc_jax.run_study`; the cells one after another).
        device: ``"cpu"``, ``"gpu"`` or ``"auto"`` (default), as in :func:`gnc_jax.run_study`.
        batch_cells: run the cells as one batch per program (:func:`gnc_jax.cells.run_cells`)
            instead of one study after another; default: on an accelerator, without a client
            (a GPU pays its loops' latency once instead of once per cell; a CPU gains nothing).
        max_hours: refuse (before any study) an envelope estimated to take longer (module
            docstring).
    """
    axes = grid_axes(grid)
    if not axes:
        raise ScenarioError("--grid: none given; allowed: one or more section.field=a:b:n")
    if isinstance(runs, bool) or not isinstance(runs, int) or runs <= 0:
        raise ScenarioError(f"runs: {runs!r}; allowed: an integer >= 1")
    if isinstance(max_hours, bool) or not isinstance(max_hours, (int, float)) or not max_hours > 0:
        raise ScenarioError(f"max_hours: {max_hours!r}; allowed: a number > 0")
    seed = check_seed(scenario.seed if seed is None else seed)
    system = scenario.system
    backend = select(device)
    _checked_cost(scenario, axes, runs, backend, max_hours, progress)
    cells = list(_cell_scenarios(scenario, axes))  # every cell validated before any study
    checks = system.envelope_check([c.config for _, c in cells], runs=runs, seed=seed)
    metrics = dict(system.envelope_metrics)
    rows = []
    t_all = time.perf_counter()
    if batch_cells is None:
        batch_cells = client is None and backend.platform != "cpu"
    batched = {}
    if batch_cells:
        if client is not None:
            raise ScenarioError("batch_cells: given with a client; allowed: one of them")
        todo = [n for n, check in enumerate(checks) if check.get("feasible", True)]
        _say(progress, f"envelope: {len(todo)} cells of {runs} runs in one batch per program")
        done = run_cells(
            [cells[n][1] for n in todo], runs, seed, device=device, max_hours=max_hours
        )
        batched = dict(zip(todo, done))
    for n, ((point, cell), check) in enumerate(zip(cells, checks)):
        row: dict[str, Any] = {"cell": n, **point, **check.get("columns", {})}
        where = ", ".join(
            f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in point.items()
        )
        head = f"[{n + 1}/{len(cells)}] {where}:"
        if not check.get("feasible", True):
            row.update(status=INFEASIBLE, reason=check.get("reason", ""))
            _say(progress, f"{head} infeasible ({row['reason']}), not simulated")
            rows.append(row)
            continue
        t0 = time.perf_counter()
        try:
            study = batched.get(n) or run_study(
                cell,
                runs=runs,
                seed=seed,
                progress=False,
                client=client,
                device=device,
                max_hours=max_hours,
            )
            if isinstance(study, ScenarioError):
                raise study
        except ScenarioError as e:
            row.update(status=REFUSED, reason=str(e))
            _say(progress, f"{head} refused: {e}")
            rows.append(row)
            continue
        s = study.summary()
        row.update(
            status=SIMULATED,
            reason="",
            runs=study.runs,
            failed=s["failed"],
            failed_fraction=s["failed"] / study.runs,
            failed_by_status=", ".join(f"{k} {v}" for k, v in s["failed_by_status"].items()),
            wall_s=study.wall_s + study.compile_s if n in batched else time.perf_counter() - t0,
            compile_s=study.compile_s,
        )
        for key in metrics:
            if key != "failed_fraction":
                v = s.get(key)
                row[key] = float(v) if isinstance(v, (int, float)) else None
        shown = ", ".join(
            f"{k} {row[k]:.4g}" for k in metrics if isinstance(row.get(k), (int, float))
        )
        _say(progress, f"{head} {study.runs} runs in {row['wall_s']:.1f} s; {shown}")
        rows.append(row)
    _say(progress, f"envelope: {len(cells)} cells in {time.perf_counter() - t_all:.1f} s")
    result = Envelope(scenario, axes, rows, metrics, runs, seed)
    if out is not None:
        result.save(out)
    return result


def _say(progress: bool, line: str) -> None:
    if progress:
        print(line, file=sys.stderr, flush=True)


__all__ = [
    "CELL_OVERHEAD_S",
    "COST_SAMPLE",
    "Envelope",
    "MAX_CELLS",
    "envelope",
    "grid_axes",
    "parse_grid",
    "SIMULATED",
    "INFEASIBLE",
    "REFUSED",
]
