"""Many CPU cores: gnc_jax's per-core throughput on 1 and N host devices, beside the numba peer.

    python benchmarks/cpu_cores.py [--cores N] [--per-core 4000] [--out FILE] [--quick]

``deep-impact-los``, seed 0, ``JAX_PLATFORMS=cpu``; every row in its own process (the host
device count is fixed when JAX starts), pinned to its cores with ``sched_setaffinity``; compile
apart, the best of two timed calls after it:

* ``gnc_jax 1 device``: one host device on one core, ``per_core`` runs;
* ``gnc_jax N devices``: N host devices on N cores (the package's default on such a machine),
  ``N x per_core`` runs, at the planner's default chunk and in one chunk;
* ``gnc_jax N processes``: N processes of one device each, one per core, started together
  after each has compiled (the bound a perfect split over devices would reach);
* ``numba 1 thread`` / ``numba N threads``: the suite's numba peer drawing its own normals
  (``benchmarks/peers/numba_impactor.py``), the same run counts.

Per-core efficiency is (runs/s over cores) / (runs/s of the one-core row of the same code):
for gnc_jax against its one-device row, for numba against its one-thread row, which also
measures what the machine itself loses when every core is busy (clock, memory bandwidth).
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENARIO = "deep-impact-los"

_GNC = r"""
import json, os, sys, time, pathlib
sys.path.insert(0, {root!r})
import gnc_jax as gj
sc = gj.load_scenario({scenario!r})
runs, chunk, sync = {runs}, {chunk}, {sync!r}
first = gj.run_study(sc, runs=runs, seed=0, chunk_size=chunk, progress=False, device="cpu")
if sync:  # wait until every sibling has compiled, then start together
    pathlib.Path(sync, f"ready-{{os.getpid()}}").touch()
    while not pathlib.Path(sync, "go").exists():
        time.sleep(0.005)
t0 = time.time()
walls = []
for _ in range(2):
    s = gj.run_study(sc, runs=runs, seed=0, chunk_size=chunk, progress=False, device="cpu")
    walls.append(s.wall_s)
print("@@" + json.dumps(dict(compile_s=first.compile_s, wall_s=min(walls), walls=walls,
      start=t0, end=time.time(), chunk=s.chunk_size, devices=len(__import__("jax").devices()),
      failed=s.summary()["failed"])))
"""

_NUMBA = r"""
import json, sys, time
sys.path.insert(0, {root!r})
import numba
import gnc_jax as gj
from benchmarks.peers import numba_impactor as peer
sc = gj.load_scenario({scenario!r})
peer.run_own(sc, 16)
timer = peer._own_timer(sc, {runs})
walls = [timer()[0] for _ in range(2)]
print("@@" + json.dumps(dict(wall_s=min(walls), walls=walls, threads=numba.get_num_threads())))
"""


def _spawn(code: str, cores: list[int], env: dict) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "JAX_PLATFORMS": "cpu", **env},
        cwd=ROOT,
        preexec_fn=lambda: os.sched_setaffinity(0, set(cores)),
    )


def _result(proc: subprocess.Popen, timeout: float) -> dict:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return dict(error="timed out")
    for line in out.splitlines():
        if line.startswith("@@"):
            return json.loads(line[2:])
    return dict(error=(err.strip().splitlines() or ["no output"])[-1][:300])


def gnc_row(cores, runs, chunk=None, timeout=300.0) -> dict:
    code = _GNC.format(root=str(ROOT), scenario=SCENARIO, runs=runs, chunk=chunk, sync=None)
    env = {"GNC_JAX_HOST_DEVICES": str(len(cores))}
    return _result(_spawn(code, cores, env), timeout)


def gnc_processes(cores, runs_each, chunk=None, timeout=300.0) -> dict:
    """One single-device process per core, timed from a common start."""
    with tempfile.TemporaryDirectory() as sync:
        code = _GNC.format(
            root=str(ROOT), scenario=SCENARIO, runs=runs_each, chunk=chunk, sync=sync
        )
        env = {"GNC_JAX_HOST_DEVICES": "1"}
        procs = [_spawn(code, [c], env) for c in cores]
        t0 = time.time()
        while len(list(pathlib.Path(sync).glob("ready-*"))) < len(procs):
            if time.time() - t0 > timeout or any(p.poll() is not None for p in procs):
                break
            time.sleep(0.02)
        pathlib.Path(sync, "go").touch()
        rows = [_result(p, timeout) for p in procs]
    if any("error" in r for r in rows):
        return dict(error=next(r["error"] for r in rows if "error" in r))
    # two timed calls each: the slowest process's first call bounds the aggregate
    span = max(r["start"] + r["walls"][0] for r in rows) - min(r["start"] for r in rows)
    return dict(wall_s=span, compile_s=max(r["compile_s"] for r in rows), processes=len(rows))


def numba_row(cores, runs, timeout=300.0) -> dict:
    code = _NUMBA.format(root=str(ROOT), scenario=SCENARIO, runs=runs)
    return _result(_spawn(code, cores, {"NUMBA_NUM_THREADS": str(len(cores))}), timeout)


def run(cores: int, per_core: int, chunks: list[int] | None = None) -> dict:
    all_cores = sorted(os.sched_getaffinity(0))[:cores]
    n = len(all_cores)
    if chunks:  # per-device chunk sweep: one core against all cores, same chunk
        cases = []
        for c in chunks:
            cases += [
                (
                    f"gnc_jax 1 device, chunk {c}",
                    1,
                    lambda c=c: gnc_row(all_cores[:1], per_core, c),
                ),
                (
                    f"gnc_jax {n} devices, chunk {c}/device",
                    n,
                    lambda c=c: gnc_row(all_cores, n * per_core, n * c),
                ),
                (
                    f"gnc_jax {n} processes, chunk {c}",
                    n,
                    lambda c=c: gnc_processes(all_cores, per_core, c),
                ),
            ]
        return _rows(cases, per_core, n, sweep=True)
    cases = [
        ("gnc_jax 1 device", 1, lambda: gnc_row(all_cores[:1], per_core)),
        (f"gnc_jax {n} devices", n, lambda: gnc_row(all_cores, n * per_core)),
        (
            f"gnc_jax {n} devices, one chunk",
            n,
            lambda: gnc_row(all_cores, n * per_core, chunk=n * per_core),
        ),
        (f"gnc_jax {n} processes", n, lambda: gnc_processes(all_cores, per_core)),
        ("numba 1 thread", 1, lambda: numba_row(all_cores[:1], per_core)),
        (f"numba {n} threads", n, lambda: numba_row(all_cores, n * per_core)),
    ]
    return _rows(cases, per_core, n)


def _rows(cases, per_core, n, sweep=False) -> dict:
    rows = []
    for name, used, case in cases:
        r = case()
        r.update(name=name, cores=used, runs=per_core * used)
        if "wall_s" in r:
            r["per_s"] = round(r["runs"] / r["wall_s"], 1)
            r["per_core_per_s"] = round(r["per_s"] / used, 1)
        rows.append(r)
        print(json.dumps(r), flush=True)
    if sweep:  # each chunk's many-core rows against its own one-device row
        for i in range(0, len(rows), 3):
            ref = rows[i].get("per_core_per_s")
            for r in rows[i : i + 3]:
                if ref and "per_core_per_s" in r:
                    r["efficiency"] = round(r["per_core_per_s"] / ref, 3)
        return dict(scenario=SCENARIO, cores=n, per_core=per_core, rows=rows)
    one = {k: next(r for r in rows if r["name"].startswith(k)) for k in ("gnc_jax", "numba")}
    for r in rows:
        ref = one["numba" if r["name"].startswith("numba") else "gnc_jax"]
        if "per_core_per_s" in r and "per_core_per_s" in ref:
            r["efficiency"] = round(r["per_core_per_s"] / ref["per_core_per_s"], 3)
    numba_n = rows[-1].get("per_s")
    for r in rows:
        if numba_n and r.get("per_s") and r["cores"] == n:
            r["vs_numba_n"] = round(r["per_s"] / numba_n, 3)
    return dict(scenario=SCENARIO, cores=n, per_core=per_core, cpu_count=os.cpu_count(), rows=rows)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cores", type=int, default=os.cpu_count())
    p.add_argument("--per-core", type=int, default=4000)
    p.add_argument("--out", default=None)
    p.add_argument("--quick", action="store_true", help="200 runs per core")
    p.add_argument(
        "--chunks",
        default="",
        help="comma-separated runs per device: sweep the chunk on 1 core, N devices, N processes",
    )
    args = p.parse_args()
    chunks = [int(c) for c in args.chunks.split(",") if c]
    result = run(args.cores, 200 if args.quick else args.per_core, chunks)
    cols = ("name", "runs", "wall_s", "per_s", "per_core_per_s", "efficiency", "vs_numba_n")
    print("| " + " | ".join(cols) + " |\n|" + "---|" * len(cols))
    for r in result["rows"]:
        print("| " + " | ".join(str(r.get(c, r.get("error", ""))) for c in cols) + " |")
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
