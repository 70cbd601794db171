"""The skip entry's acceptance grids: four vehicles, entry angle x downrange, 200 runs per cell.

    python benchmarks/entry_grids.py --out DIR [--procs 15] [--runs 200] [--only v1,ld022]
        [--budget 540] [--keep-designs] [--reach-3d] [--from-json CELLS]

Vehicles (``lunar-skip-entry`` with ``--set`` overrides): ``v1`` the packaged capsule (L/D
0.30, β 315 kg/m²), ``v2`` L/D 0.25 / β 450, ``ld040`` L/D 0.40 / β 250, ``ld022`` L/D 0.22 /
β 600. Each (vehicle, entry angle) row of cells is one ``gj.envelope`` call in its own process
(one CPU core each: ``JAX_PLATFORMS=cpu``, one host device, XLA's thread pool off); ``--procs``
processes at once. Each row writes ``DIR/<vehicle>_<fpa>/cells.parquet``; the merged table,
``DIR/cells.json``, and one markdown table per vehicle (``ok`` % / chute 3σ km, with the share
of runs whose own dispersed footprint holds the target with margin in brackets; a cell counts
when that share is ≥ 99.5 %; **bold**: a counted cell that meets ≥ 99.5 % ``ok`` and 3σ ≤ 5 km)
are printed at the end. Rows that cannot start within ``--budget`` seconds are skipped, saying
so. ``--keep-designs`` copies the reference designs into ``DIR/designs`` (the design cache).

The pre-check's footprints are in downrange only. ``--reach-3d`` (also with ``--from-json``)
checks each counted cell that misses the bar in three dimensions: it flies the cell's study
again and, for each run that is not ``ok``, the run's own dispersed vehicle at every constant
bank magnitude reversed once (:func:`gnc_jax.systems.capsule.envelope.target_reach`, 10-20 s
a run); a run none of whose flights comes to the target in crossrange cannot reach it. A cell
whose runs that cannot reach exceed 0.5 % no longer counts (its table entry says how many).
"""

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
VEHICLES = {
    "v1": ([], [-7.1, -6.8, -6.5, -6.2, -5.9, -5.6, -5.3], [2500, 4000, 6000, 8000, 10000]),
    "v2": (
        ["vehicle.cl=0.325", "vehicle.mass_kg=12870"],
        [-7.2, -6.9, -6.6, -6.3, -6.0, -5.7, -5.4],
        [2500, 4000, 6000, 8000, 10000],
    ),
    "ld040": (
        ["vehicle.cl=0.52", "vehicle.mass_kg=7150"],
        [-7.0, -6.5, -6.0, -5.5, -5.2],
        [2500, 5000, 8000, 10000],
    ),
    "ld022": (
        ["vehicle.cl=0.286", "vehicle.mass_kg=17160"],
        [-7.2, -6.8, -6.4, -6.0, -5.6],
        [2500, 5000, 8000, 10000],
    ),
}


def row_job(vehicle: str, fpa: float, runs: int, out: pathlib.Path) -> None:
    import gnc_jax as gj

    overrides, _, ranges = VEHICLES[vehicle]
    scenario = gj.load_scenario("lunar-skip-entry", overrides)
    grid = {"entry.fpa_deg": [fpa], "entry.range_km": [float(r) for r in ranges]}
    gj.envelope(scenario, grid, runs=runs, seed=0, out=out, device="cpu")


def one_process_env() -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu", GNC_JAX_HOST_DEVICES="1")
    env["XLA_FLAGS"] = "--xla_cpu_multi_thread_eigen=false"
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH", "")]))
    return env


def table(vehicle: str, cells: list[dict]) -> str:
    _, fpas, ranges = VEHICLES[vehicle]
    at = {(c["entry.fpa_deg"], c["entry.range_km"]): c for c in cells}
    lines = [
        "| range \\ FPA | " + " | ".join(f"{f:g}°" for f in fpas) + " |",
        "|---" * (len(fpas) + 1) + "|",
    ]
    counted = met = 0
    for r in sorted(ranges, reverse=True):
        out = []
        for f in fpas:
            c = at.get((f, float(r)))
            if c is None:
                out.append("not run")
                continue
            reach = c.get("reachable_fraction_margin")
            reach_s = "" if reach is None or reach != reach else f" ({100 * reach:.1f} %)"
            counts = reach is not None and reach >= 0.995
            cannot = c.get("cannot_reach_3d")
            if cannot is not None and cannot == cannot:
                counts = counts and cannot <= 0.005 * c["runs"]
                reach_s += f" [3-D: {int(cannot)} cannot reach]"
            if c["status"] != "simulated":
                out.append(f"{c['status']}{reach_s}" + ("" if counts else " ·"))
                counted += counts
                continue
            ok, sig = 100 * (1 - c["failed_fraction"]), c.get("chute_3sigma_km")
            good = ok >= 99.5 and sig is not None and sig <= 5.0
            text = f"{ok:.1f} % / {sig:.1f}{reach_s}"
            if counts and not good and c.get("failed_by_status"):
                text += f", failed: {c['failed_by_status']}"  # why a counted cell misses the bar
            counted += counts
            met += counts and good
            out.append(f"**{text}**" if counts and good else text + ("" if counts else " ·"))
        lines.append(f"| {r} km | " + " | ".join(out) + " |")
    return f"{vehicle}: {counted} cells count, {met} meet the bar\n" + "\n".join(lines)


def misses_the_bar(c: dict) -> bool:
    """A simulated cell that the pre-check counts and that misses ≥ 99.5 % ``ok`` or 3σ ≤ 5 km."""
    reach = c.get("reachable_fraction_margin")
    if c["status"] != "simulated" or reach is None or not reach >= 0.995:
        return False
    sig = c.get("chute_3sigma_km")
    return 1 - c["failed_fraction"] < 0.995 or sig is None or not sig <= 5.0


def reach_3d(cells: dict) -> None:
    """``cannot_reach_3d`` of each counted cell that misses the bar: its runs that are not
    ``ok`` and that no constant bank magnitude reversed once brings to the target (a run that
    read ``overload`` is left out: its failure is the load it flew, not where it landed)."""
    import numpy as np

    import gnc_jax as gj
    from gnc_jax.systems.capsule.envelope import target_reach

    for v, cs in cells.items():
        overrides = VEHICLES[v][0]
        for c in filter(misses_the_bar, cs):
            fpa, rng = c["entry.fpa_deg"], c["entry.range_km"]
            scenario = gj.load_scenario(
                "lunar-skip-entry", [*overrides, f"entry.fpa_deg={fpa}", f"entry.range_km={rng}"]
            )
            study = gj.run_study(scenario, runs=int(c["runs"]), seed=0, progress=False)
            failed = np.flatnonzero(
                (study.status != gj.Status.ok) & (study.status != gj.Status.overload)
            )
            spans = target_reach(scenario.config, failed, seed=0)
            cannot = [int(i) for i, (lo, hi) in zip(failed, spans) if not lo <= 0.0 <= hi]
            c["cannot_reach_3d"] = float(len(cannot))
            print(
                f"{v} {fpa:g}°/{rng:g} km: {len(failed)} runs neither ok nor overload, "
                f"cannot reach: {cannot}"
            )


def report(cells: dict, out: pathlib.Path, runs: int) -> int:
    """Print each vehicle's table; write its heat maps into ``out/<vehicle>``."""
    import gnc_jax as gj
    from gnc_jax.operating_envelope import Envelope

    for v, cs in cells.items():
        print(table(v, cs), flush=True)
        overrides, fpas, ranges = VEHICLES[v]
        scenario = gj.load_scenario("lunar-skip-entry", overrides)
        axes = {"entry.fpa_deg": fpas, "entry.range_km": [float(r) for r in ranges]}
        metrics = dict(scenario.system.envelope_metrics)
        Envelope(scenario, axes, cs, metrics, runs, 0).save(out / v)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True)
    p.add_argument("--procs", type=int, default=max(1, (os.cpu_count() or 2) - 1))
    p.add_argument("--runs", type=int, default=200)
    p.add_argument("--only", default=",".join(VEHICLES))
    p.add_argument("--budget", type=float, default=float("inf"), help="seconds to start rows")
    p.add_argument("--keep-designs", action="store_true")
    p.add_argument("--from-json", default=None, help="tables and heat maps of a cells.json")
    p.add_argument("--reach-3d", action="store_true", help="three-dimensional reach of the misses")
    p.add_argument("--row", default=None, help=argparse.SUPPRESS)  # a child: vehicle:fpa:core
    a = p.parse_args(argv)
    out = pathlib.Path(a.out)
    if a.row:
        vehicle, fpa, core = a.row.split(":")
        if hasattr(os, "sched_setaffinity") and 0 <= int(core) < (os.cpu_count() or 1):
            os.sched_setaffinity(0, {int(core)})
        row_job(vehicle, float(fpa), a.runs, out / f"{vehicle}_{fpa}")
        return 0
    if a.from_json:
        cells = json.loads(pathlib.Path(a.from_json).read_text())
        if a.reach_3d:
            reach_3d(cells)
            out.mkdir(parents=True, exist_ok=True)
            (out / "cells.json").write_text(json.dumps(cells, indent=1, default=float))
        return report(cells, out, a.runs)
    rows = [(v, f) for v in a.only.split(",") for f in VEHICLES[v][1]]
    t0, running, logs = time.perf_counter(), [], out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    while rows or running:
        running = [r for r in running if r[2].poll() is None]
        while rows and len(running) < a.procs:
            core = min(set(range(a.procs)) - {r[1] for r in running})
            v, f = rows.pop(0)
            if time.perf_counter() - t0 > a.budget:
                print(f"{v} {f}°: skipped, past the budget", flush=True)
                continue
            pin = core if a.procs <= (os.cpu_count() or 1) else -1  # more rows than cores: unpinned
            log = open(logs / f"{v}_{f}.log", "w")
            cmd = [sys.executable, __file__, "--out", str(out), "--runs", str(a.runs)]
            proc = subprocess.Popen(
                [*cmd, "--row", f"{v}:{f}:{pin}"], env=one_process_env(), stdout=log, stderr=log
            )
            running.append(((v, f), core, proc))
        time.sleep(1.0)
    import pyarrow.parquet as pq

    cells = {v: [] for v in a.only.split(",")}
    for path in sorted(out.glob("*_*/cells.parquet")):
        vehicle = path.parent.name.rsplit("_", 1)[0]
        if vehicle in cells:
            cells[vehicle] += pq.read_table(path).to_pylist()
    if a.reach_3d:
        reach_3d(cells)
    (out / "cells.json").write_text(json.dumps(cells, indent=1, default=float))
    report(cells, out, a.runs)
    if a.keep_designs:
        from gnc_jax.guidance.entry.cache import cache_dir

        shutil.copytree(cache_dir(), out / "designs", dirs_exist_ok=True)
    print(f"all rows in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
