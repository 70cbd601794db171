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
line naming the field.
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
from .scenario import Scenario, ScenarioError
from .study import run_study

SIMULATED, INFEASIBLE, REFUSED = "simulated", "infeasible", "refused"


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
            values = np.linspace(float(a), float(b), n_val).tolist()
        else:
            values = [float(x) for x in text.split(",")]
    except ValueError:
        raise ScenarioError(
            f"--grid {spec}: {text!r} is not a:b:n or a list of numbers; allowed: two numbers "
            "and a whole number of values n >= 1 (e.g. -6.5:-5.5:5), or v1,v2,..."
        ) from None
    if not all(math.isfinite(v) for v in values):
        raise ScenarioError(f"--grid {spec}: values must be finite numbers")
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
    **check_options,
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
        check_options: passed to the system's pre-check (the capsule: ``load_limit_g``).
    """
    axes = dict(parse_grid(g) for g in grid) if not isinstance(grid, dict) else dict(grid)
    if not axes:
        raise ScenarioError("--grid: none given; allowed: one or more section.field=a:b:n")
    if isinstance(runs, bool) or not isinstance(runs, int) or runs <= 0:
        raise ScenarioError(f"runs: {runs!r}; allowed: an integer >= 1")
    seed = scenario.seed if seed is None else seed
    system = scenario.system
    cells = list(_cell_scenarios(scenario, axes))  # every cell validated before any study
    checks = system.envelope_check(
        [c.config for _, c in cells], runs=runs, seed=seed, **check_options
    )
    metrics = dict(system.envelope_metrics)
    rows = []
    t_all = time.perf_counter()
    if batch_cells is None:
        batch_cells = client is None and select(device).platform != "cpu"
    batched = {}
    if batch_cells:
        if client is not None:
            raise ScenarioError("batch_cells: given with a client; allowed: one of them")
        todo = [n for n, check in enumerate(checks) if check.get("feasible", True)]
        _say(progress, f"envelope: {len(todo)} cells of {runs} runs in one batch per program")
        done = run_cells([cells[n][1] for n in todo], runs, seed, device=device)
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
                cell, runs=runs, seed=seed, progress=False, client=client, device=device
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


__all__ = ["Envelope", "envelope", "parse_grid", "SIMULATED", "INFEASIBLE", "REFUSED"]
