"""The result of an error budget: the table (metric x source x method, with intervals), its
checks, ``budget.json`` and ``budget.parquet`` (read back by ``gnc-jax report``)."""

import dataclasses
import json
import pathlib
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from ..scenario import Scenario
from .estimators import MIN_RUNS

METHOD_LABELS = {
    "first_order": "first order",
    "total": "total",
    "one_at_a_time": "one at a time",
    "linear": "linear",
}
BUDGET_JSON, BUDGET_TABLE, BUDGET_RUNS = "budget.json", "budget.parquet", "budget_runs.parquet"


@dataclasses.dataclass
class Budget:
    """An error budget (:func:`gnc_jax.budget`).

    Attributes:
        rows: one dict per metric, source (factor) and method: ``share`` of the metric's
            variance (a Sobol index, or a variance over the all-on variance), its interval
            ``share_lo``/``share_hi``, and the ``variance`` it stands for (metric units^2).
        checks: per metric: the all-on ``variance``, the sum of the first-order indices and
            the interaction share with intervals, ``first_sum_le_1``, ``total_ge_first``,
            and the sums of the one-at-a-time and linear shares.
        counts: runs per design and the runs each method kept (all its designs ``ok``).
        factors: ``{factor: (source, ...)}``; inactive: sources whose magnitudes are zero.
        nominal: the all-off run's metrics and status.
        wall_s, compile_s, linear_s: wall time of the whole budget, its compilation, and the
            linear method's share of it; linear_error: why the linear method could not run.
        samples: ``{design: (metric x run values, ok per run)}``: ``all_on`` (the study),
            ``b``, ``ab:<source>``, ``oat:<source>``, ``linear:<source>`` (the linearised
            responses); written as ``budget_runs.parquet``.
    """

    scenario: Scenario
    runs: int
    seed: int
    metrics: list
    factors: dict
    inactive: list
    methods: list
    rows: list
    checks: dict
    counts: dict
    nominal: dict
    wall_s: float
    compile_s: float
    linear_s: float | None = None
    linear_error: str | None = None
    samples: dict | None = dataclasses.field(default=None, repr=False)

    def share(self, metric: str, source: str, method: str) -> dict:
        """The row of ``metric``, ``source`` and ``method``."""
        for r in self.rows:
            if (r["metric"], r["source"], r["method"]) == (metric, source, method):
                return r
        raise KeyError((metric, source, method))

    def table(self) -> pa.Table:
        return pa.Table.from_pylist(self.rows)

    def runs_table(self) -> pa.Table:
        """One row per design and run: ``design``, ``run``, ``ok`` and each metric."""
        cols: dict = {"design": [], "run": [], "ok": [], **{m: [] for m in self.metrics}}
        for design, (values, ok) in (self.samples or {}).items():
            cols["design"] += [design] * len(ok)
            cols["run"] += list(range(len(ok)))
            cols["ok"] += [bool(x) for x in ok]
            for j, m in enumerate(self.metrics):
                cols[m] += [float(x) for x in values[j]]
        return pa.table(cols)

    def to_dict(self) -> dict[str, Any]:
        return dict(
            scenario=self.scenario.name,
            kind=self.scenario.kind,
            runs=self.runs,
            seed=self.seed,
            metrics=self.metrics,
            factors={k: list(v) for k, v in self.factors.items()},
            inactive=self.inactive,
            methods=self.methods,
            checks=self.checks,
            counts=self.counts,
            nominal=self.nominal,
            wall_s=self.wall_s,
            compile_s=self.compile_s,
            linear_s=self.linear_s,
            linear_error=self.linear_error,
            rows=self.rows,
        )

    def save(self, out_dir) -> list[pathlib.Path]:
        """``budget.json``, ``budget.parquet``, ``budget_runs.parquet`` and ``scenario.toml``
        in ``out_dir``."""
        out = pathlib.Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / BUDGET_JSON).write_text(json.dumps(self.to_dict(), indent=1, default=float))
        pq.write_table(self.table(), out / BUDGET_TABLE)
        pq.write_table(self.runs_table(), out / BUDGET_RUNS)
        (out / "scenario.toml").write_text(self.scenario.to_toml())
        return [out / BUDGET_JSON, out / BUDGET_TABLE, out / BUDGET_RUNS, out / "scenario.toml"]

    def __str__(self) -> str:
        return format_table(self.to_dict())


def format_table(budget: dict) -> str:
    """Plain-text tables of a budget (``budget.json``'s content): one per metric, a row per
    source, a column per method (share and interval, in per cent)."""
    methods = [m for m in METHOD_LABELS if any(r["method"] == m for r in budget["rows"])]
    counts = budget.get("counts", {})
    short = [
        f"{m}: {counts[f'{m}_ok']} < {MIN_RUNS} ok runs"
        for m in budget["methods"]
        if counts.get(f"{m}_ok", MIN_RUNS) < MIN_RUNS
    ]
    lines = []
    for metric in budget["metrics"]:
        c = budget["checks"].get(metric, {})
        variance = c.get("variance", c.get("all_on_variance", float("nan")))
        if not c and short:
            lines.append(f"{metric}: too few ok runs to share its variance ({'; '.join(short)})")
            continue
        if not variance > 0:
            lines.append(f"{metric}: no variance (the same in every run): nothing to share")
            continue
        head = f"{metric}: variance {variance:.4g}"
        if "interaction" in c:
            head += (
                f", first-order sum {c['first_sum']:.2f} [{c['first_sum_lo']:.2f}, "
                f"{c['first_sum_hi']:.2f}], interactions {c['interaction']:.2f}"
            )
        lines += [head, f"  {'source':<22}" + "".join(f"{METHOD_LABELS[m]:>22}" for m in methods)]
        for source in budget["factors"]:
            cells = []
            for m in methods:
                r = next(
                    (
                        r
                        for r in budget["rows"]
                        if (r["metric"], r["source"], r["method"]) == (metric, source, m)
                    ),
                    None,
                )
                cells.append(
                    "-".rjust(22)
                    if r is None
                    else f"{100 * r['share']:6.1f} [{100 * r['share_lo']:5.1f},"
                    f"{100 * r['share_hi']:6.1f}]".rjust(22)
                )
            lines.append(f"  {source:<22}" + "".join(cells))
        if short:
            lines.append(f"  not estimated ({'; '.join(short)})")
    return "\n".join(lines)


__all__ = ["BUDGET_JSON", "BUDGET_TABLE", "Budget", "METHOD_LABELS", "format_table"]
