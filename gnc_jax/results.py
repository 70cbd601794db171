"""Study results: summary statistics, ``summary.json``, the runs table and the resolved TOML.

Only runs whose status is ``ok`` enter the statistics; the others are counted in ``failed``
(with a count per status) and flagged in the runs table (``runs/``, see ``gnc_jax.store``).
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
from .backend import describe_line
from .scenario import ScenarioError, load_scenario
from .systems.base import get_system


def _machine_note(study) -> str:
    if study.device:
        return describe_line(study.device)
    return (
        f"{platform.machine()} {os.cpu_count()} cores, {study.n_devices} XLA host devices, "
        f"jax {jax.__version__}, {platform.python_implementation()} "
        f"{platform.python_version()}"
    )


class _Columns(dict):
    """The outcome columns of a study on disk read so far; a column asked for later (one that
    a statistic reads only on a branch the first chunk's runs did not take) is read then."""

    def __init__(self, study, columns: dict, names):
        super().__init__(columns)
        self._study, self._names = study, set(names)

    def __missing__(self, k):
        if k not in self._names:
            raise KeyError(k)
        self[k] = self._study.columns([k])[k]
        return self[k]

    def __contains__(self, k):
        return k in self._names

    def get(self, k, default=None):
        return self[k] if k in self._names else default


def _statistics_outcomes(study, system) -> dict:
    """The outcomes the system's statistics read: everything for a study in memory; for one
    on disk, the columns that its statistics use on the first chunk, so that the summary of a
    study of millions of runs reads a few columns, not the whole table (any other column it
    asks for is read when asked)."""
    if study.path is None:
        return study.outcomes
    from .store import chunk_files, outcomes_from_table

    table = pq.read_table(chunk_files(study.path)[0])
    shapes = json.loads(table.schema.metadata[b"gnc_jax.shapes"])
    sample = outcomes_from_table(table, shapes)

    class Recording(dict):
        def __getitem__(self, k):
            used.add(k)
            return dict.__getitem__(self, k)

        def get(self, k, default=None):
            used.add(k)
            return dict.get(self, k, default)

    used: set = set()
    ok = sample["status"] == Status.ok
    try:
        if ok.any():
            system.statistics(Recording(sample), ok)
        else:
            used = set(shapes)
    except Exception:  # the probe is an optimisation: read everything instead
        used = set(shapes)
    return _Columns(study, study.columns(sorted(used | {"status"})), shapes)


def summarize(study) -> dict[str, Any]:
    """The ``summary.json`` content of a study."""
    status = study.status
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
        write_s=round(study.write_s, 4),
        runs_per_s=round(study.runs / study.wall_s, 2) if study.wall_s > 0 else None,
        chunk_size=study.chunk_size,
        machine=_machine_note(study),
    )
    if study.device:
        out["device"] = dict(study.device)
    system = get_system(sc.kind)
    if system.laws():
        out["law"] = sc.config["guidance"]["law"]
    if study.workers:
        out["dask_workers"] = study.workers
    warnings = system.warnings(sc.config)
    if warnings:
        out["warnings"] = warnings
    if ok.any():
        out.update(system.statistics(_statistics_outcomes(study, system), ok))
    else:
        out["statistics"] = "none: no run is ok (see failed_by_status)"
    out["paper"] = dict(sc.paper)
    return out


def runs_table(study):
    """One row per run: index, status, outcomes and dispersion draws (vectors split in columns)."""
    from .store import chunk_table, read_runs

    if study.path is not None:
        return read_runs(study.path)
    return chunk_table(study.outcomes, 0)


def save_study(study, out_dir, overwrite: bool = False) -> dict[str, str]:
    """Write a study into ``out_dir`` in the layout of ``gnc_jax.store`` (``summary.json``,
    ``runs/`` chunk files, ``scenario.toml``, ``study.json``). A directory holding another
    study is refused unless ``overwrite``; a study already written there is left as it is."""
    import hashlib

    from .store import StudyStore, code_version

    out = pathlib.Path(out_dir)
    paths = {
        "summary": out / "summary.json",
        "runs": out / "runs",
        "scenario": out / "scenario.toml",
    }
    if study.path is not None and pathlib.Path(study.path).resolve() == out.resolve():
        return {k: str(v) for k, v in paths.items()}
    manifest = dict(
        scenario_name=study.scenario.name,
        kind=study.scenario.kind,
        scenario_sha256=hashlib.sha256(study.scenario.to_toml().encode()).hexdigest(),
        seed=study.seed,
        runs=study.runs,
        chunk_size=study.chunk_size,
        code_version=code_version(),
    )
    outcomes = study.outcomes
    with StudyStore(out, manifest, overwrite=overwrite) as store:
        for c, start in enumerate(range(0, study.runs, study.chunk_size)):
            stop = min(start + study.chunk_size, study.runs)
            store.write_chunk(c, start, {k: v[start:stop] for k, v in outcomes.items()})
        store.finish(study.summary(), study.scenario.to_toml())
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
    """The runs table of ``path``: a study's ``runs/`` directory of chunk files (or the single
    ``runs.parquet`` of earlier versions); a damaged file is named."""
    files = sorted(path.glob("chunk-*.parquet")) if path.is_dir() else [path]
    if not files:
        raise ResultsError(f"{path}: no chunk files; run `gnc-jax run ... --out {path.parent}`")
    tables = []
    for f in files:
        try:
            tables.append(pq.read_table(f))
        except (pa.ArrowException, OSError) as e:
            first = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise ResultsError(f"{f}: not a readable Parquet file ({first}; truncated?)") from None
    try:
        table = pa.concat_tables([t.replace_schema_metadata(None) for t in tables])
    except pa.ArrowException as e:
        raise ResultsError(f"{path}: chunk files of different layouts ({e})") from None
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
        what = "a file, not a directory" if out.exists() else "no such directory"
        raise ResultsError(
            f"{out}: {what}; allowed: a directory written by `gnc-jax run ... --out DIR`"
        )
    manifest = out / "study.json"
    if manifest.is_file():
        try:
            state = json.loads(manifest.read_text()).get("state")
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError):
            raise ResultsError(f"{manifest}: not a readable study manifest (damaged?)") from None
        if state != "complete":
            from .store import chunk_files

            raise ResultsError(
                f"{out}: a partial study ({len(chunk_files(out))} chunks written, no summary); "
                "the same `gnc-jax run ... --out DIR` command with --resume completes it"
            )
    legacy = not manifest.is_file() and not (out / "runs").is_dir()  # before chunk files
    runs_path = out / "runs.parquet" if legacy else out / "runs"
    if not (out / "summary.json").exists():
        _refuse_other_output(out)
    for path in (out / "summary.json", runs_path, out / "scenario.toml"):
        if not path.exists():
            raise ResultsError(f"{path}: missing; run `gnc-jax run ... --out {out}`")
    try:
        summary = _read_summary(out / "summary.json")
        runs = _read_runs(runs_path, summary["runs"])
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


def _refuse_other_output(out: pathlib.Path) -> None:
    """:class:`ResultsError` for the directory of an envelope (``cells.parquet``) or a tuning
    (``training.json``), whose commands write their own figures; nothing for another."""
    if (out / "cells.parquet").is_file():
        raise ResultsError(
            f"{out}: an envelope's directory (cells.parquet), whose heat maps `gnc-jax envelope` "
            "wrote there; allowed: a directory written by `gnc-jax run ... --out DIR`"
        )
    if (out / "training.json").is_file():
        raise ResultsError(
            f"{out}: a tuning's directory (training.json), whose training.png `gnc-jax tune` "
            f"wrote there; allowed: a study of its gains, `gnc-jax run {out / 'tuned.toml'} "
            "--out DIR`, then `gnc-jax report DIR`"
        )
