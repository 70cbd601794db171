"""Study results: summary statistics, ``summary.json``, ``runs.parquet`` and the resolved TOML.

Only runs whose status is ``ok`` enter the statistics; the others are counted in ``failed``
(with a count per status) and flagged in ``runs.parquet``.
"""

import json
import os
import pathlib
import platform
from typing import Any

import jax
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ._status import Status
from .scenario import ScenarioError, load_scenario
from .systems.base import get_system


def _machine_note(study) -> str:
    return (
        f"{platform.machine()} {os.cpu_count()} cores, {study.n_devices} XLA host devices, "
        f"jax {jax.__version__}, {platform.python_implementation()} "
        f"{platform.python_version()}"
    )


def summarize(study) -> dict[str, Any]:
    """The ``summary.json`` content of a study."""
    status = study.outcomes["status"]
    ok = status == Status.ok
    failed = {Status(int(s)).name: int(np.sum(status == s)) for s in np.unique(status) if s != 0}
    sc = study.scenario
    out: dict[str, Any] = dict(
        scenario=sc.name,
        kind=sc.kind,
        description=sc.description,
        runs=study.runs,
        failed=int(np.sum(~ok)),
        failed_by_status=failed,
        seed=study.seed,
        wall_s=round(study.wall_s, 4),
        compile_s=round(study.compile_s, 4),
        runs_per_s=round(study.runs / study.wall_s, 2) if study.wall_s > 0 else None,
        chunk_size=study.chunk_size,
        machine=_machine_note(study),
    )
    system = get_system(sc.kind)
    if system.laws():
        out["law"] = sc.config["guidance"]["law"]
    warnings = system.warnings(sc.config)
    if warnings:
        out["warnings"] = warnings
    if ok.any():
        out.update(system.statistics(study.outcomes, ok))
    else:
        out["statistics"] = "none: no run is ok (see failed_by_status)"
    out["paper"] = dict(sc.paper)
    return out


def runs_table(study):
    """One row per run: index, status, outcomes and dispersion draws (vectors split in columns)."""
    cols: dict[str, Any] = {"run": np.arange(study.runs)}
    status = study.outcomes["status"]
    cols["status"] = status
    cols["status_name"] = [Status(int(s)).name for s in status]
    for name, arr in study.outcomes.items():
        if name == "status":
            continue
        if arr.ndim == 1:
            cols[name] = arr
        else:
            flat = arr.reshape(arr.shape[0], -1)
            for j in range(flat.shape[1]):
                cols[f"{name}_{j}"] = flat[:, j]
    return pa.table(cols)


def save_study(study, out_dir) -> dict[str, str]:
    """Write ``summary.json``, ``runs.parquet`` and ``scenario.toml`` into ``out_dir``."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "summary": out / "summary.json",
        "runs": out / "runs.parquet",
        "scenario": out / "scenario.toml",
    }
    paths["summary"].write_text(json.dumps(study.summary(), indent=2) + "\n")
    pq.write_table(runs_table(study), paths["runs"])
    paths["scenario"].write_text(study.scenario.to_toml())
    return {k: str(v) for k, v in paths.items()}


class ResultsError(ValueError):
    """A results directory that cannot be read: the message is one line naming the file and
    what is wrong with it."""


_SUMMARY_KEYS = ("scenario", "kind", "runs", "failed")


def _read_summary(path: pathlib.Path) -> dict:
    try:
        summary = json.loads(path.read_text())
    except UnicodeDecodeError:
        raise ResultsError(f"{path}: not UTF-8 text (damaged?)") from None
    except json.JSONDecodeError as e:
        raise ResultsError(
            f"{path}: not valid JSON ({e.msg} at line {e.lineno}; damaged or truncated?)"
        ) from None
    if not isinstance(summary, dict) or any(k not in summary for k in _SUMMARY_KEYS):
        missing = [k for k in _SUMMARY_KEYS if not isinstance(summary, dict) or k not in summary]
        raise ResultsError(f"{path}: not a gnc_jax summary (missing {', '.join(missing)})")
    runs = summary["runs"]
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ResultsError(f"{path}: 'runs' is {runs!r}; expected an integer >= 1")
    return summary


def _read_runs(path: pathlib.Path, n_runs: int) -> dict:
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as e:
        first = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ResultsError(f"{path}: not a readable Parquet file ({first}; truncated?)") from None
    if "status" not in table.column_names:
        raise ResultsError(f"{path}: no 'status' column; not written by gnc_jax")
    if table.num_rows != n_runs:
        raise ResultsError(
            f"{path}: {table.num_rows} rows, but summary.json says {n_runs} runs (partial or "
            "mixed-up files?)"
        )
    return {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}


def load_results(out_dir) -> tuple[dict, "Any", "Any"]:
    """Read back ``(summary, runs table as a dict of numpy arrays, scenario)`` from a run dir.

    Raises:
        ResultsError: a missing directory or file, or a damaged, truncated or inconsistent
            one; the message names the file.
    """
    out = pathlib.Path(out_dir)
    if not out.is_dir():
        raise ResultsError(
            f"{out}: no such directory; allowed: a directory written by `gnc-jax run ... --out DIR`"
        )
    for name in ("summary.json", "runs.parquet", "scenario.toml"):
        if not (out / name).is_file():
            raise ResultsError(f"{out / name}: missing; run `gnc-jax run ... --out {out}`")
    try:
        summary = _read_summary(out / "summary.json")
        runs = _read_runs(out / "runs.parquet", summary["runs"])
    except PermissionError as e:
        raise ResultsError(f"{e.filename}: cannot read ({e.strerror})") from None
    try:
        scenario = load_scenario(out / "scenario.toml")
    except ScenarioError as e:
        raise ResultsError(f"{out / 'scenario.toml'}: {e}") from None
    if scenario.kind != summary["kind"]:
        raise ResultsError(
            f"{out / 'scenario.toml'}: kind {scenario.kind!r}, but summary.json says "
            f"{summary['kind']!r} (mixed-up files?)"
        )
    return summary, runs, scenario
