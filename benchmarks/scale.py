"""Scale-out: 1 device, 2 devices and a 2-worker local Dask cluster; memory in N.

    python benchmarks/scale.py [--quick]

* **throughput** -- ``deep-impact-los`` and ``lunar-skip-entry`` studies through
  ``gj.run_study``: on one XLA host device, on two (one per core, the default), and on a local
  Dask cluster of two worker processes (``local_cluster(2)``) of one device each and of two
  (its default), as runs/s and the ratio to one device. Each configuration runs in its own
  process (the device count is fixed when JAX starts), once to compile (and, for Dask, to fill
  the persistent compilation cache) and then timed; compile time is reported apart.
* **memory** -- a ``deep-impact-los`` study written to a directory (``out=``: every chunk to
  disk as it finishes, the summary from the chunk files) at 10k, 100k and 1M runs, each in a
  fresh process: its peak resident memory, which must not grow with N.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, os, resource, shutil, sys, tempfile, time
sys.path.insert(0, {root!r})
import gnc_jax as gj
sc = gj.load_scenario({scenario!r})
kw = {kwargs!r}
out = None
if kw.pop("to_disk", False):
    out = tempfile.mkdtemp(prefix="gnc-scale-")
warm = kw.pop("warm", 0)
workers = kw.pop("workers", None)
host_devices = kw.pop("host_devices", None)
if workers:  # one cluster for the warm-up and the timed study: its workers keep their compile
    from gnc_jax.montecarlo import local_cluster
    kw["client"] = local_cluster(workers, host_devices=host_devices)
if warm:
    gj.run_study(sc, runs=warm, progress=False, **kw)
t0 = time.perf_counter()
s = gj.run_study(sc, runs={runs}, progress=False, out=out, **kw)
summ = s.summary()
total = time.perf_counter() - t0
res = dict(wall_s=s.wall_s, compile_s=s.compile_s, total_s=total, failed=summ["failed"],
           peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
if out:
    shutil.rmtree(out)
print("@@" + json.dumps(res))
"""


def _child(scenario, runs, env=None, **kwargs):
    code = _CHILD.format(root=str(ROOT), scenario=scenario, runs=runs, kwargs=kwargs)
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
    )
    line = [x for x in proc.stdout.splitlines() if x.startswith("@@")]
    if proc.returncode or not line:
        raise RuntimeError(f"{scenario} {runs} {kwargs}: {proc.stderr.strip()[-800:]}")
    return json.loads(line[-1][2:])


def throughput(scenario, runs, warm):
    cache = tempfile.mkdtemp(prefix="gnc-jax-xla-")
    configs = {
        "1 device": dict(env={"GNC_JAX_HOST_DEVICES": "1"}),
        "2 devices": dict(env={"GNC_JAX_HOST_DEVICES": "2"}),
        "Dask, 2 workers x 1 device": dict(
            env={"JAX_COMPILATION_CACHE_DIR": cache}, workers=2, host_devices=1
        ),
        "Dask, 2 workers x 2 devices (default)": dict(
            env={"JAX_COMPILATION_CACHE_DIR": cache}, workers=2
        ),
    }
    rows = []
    for name, cfg in configs.items():
        env = cfg.pop("env")
        r = _child(scenario, runs, env=env, warm=warm, **cfg)
        rows.append(dict(scenario=scenario, config=name, runs=runs, **r))
    base = rows[0]["runs"] / rows[0]["wall_s"]
    for r in rows:
        r["runs_per_s"] = r["runs"] / r["wall_s"]
        r["vs_1_device"] = r["runs_per_s"] / base
    return rows


def memory(sizes):
    rows = []
    for n in sizes:
        t0 = time.perf_counter()
        r = _child("deep-impact-los", n, to_disk=True)
        rows.append(dict(runs=n, elapsed_s=time.perf_counter() - t0, **r))
    return rows


def run(quick: bool = False) -> dict:
    if quick:
        tp = throughput("deep-impact-los", 2000, 200) + throughput("lunar-skip-entry", 256, 32)
        mem = memory([1000, 10_000])
    else:
        tp = throughput("deep-impact-los", 20_000, 200) + throughput("lunar-skip-entry", 2000, 32)
        mem = memory([10_000, 100_000, 1_000_000])
    lines = [
        "| scenario | configuration | runs | wall (s) | runs/s | vs 1 device | compile (s) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in tp:
        lines.append(
            f"| {r['scenario']} | {r['config']} | {r['runs']:,} | {r['wall_s']:.2f} | "
            f"{r['runs_per_s']:,.0f} | {r['vs_1_device']:.2f} | {r['compile_s']:.1f} |"
        )
    lines += [
        "",
        "| deep-impact-los study to disk | wall (s) | runs/s | peak RSS (MB) | failed |",
        "|---:|---:|---:|---:|---:|",
    ]
    for r in mem:
        lines.append(
            f"| {r['runs']:,} | {r['wall_s']:.1f} | {r['runs'] / r['wall_s']:,.0f} | "
            f"{r['peak_rss_mb']:.0f} | {r['failed']} |"
        )
    return dict(
        title="Scale-out: devices, Dask workers, memory against N",
        rows=tp + mem,
        markdown="\n".join(lines),
        notes=[
            "each row a fresh process; wall after compilation; Dask: a LocalCluster of 2 worker "
            "processes (1 or 2 XLA devices each, gnc_jax.montecarlo.local_cluster), warmed by a "
            "first study on the same cluster, so its workers have compiled",
            "memory rows: run_study(out=DIR), chunks written as they finish, summary read from "
            "the chunk files (only the columns the statistics use)",
        ],
    )


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--only", choices=["throughput", "memory"], default=None)
    args = p.parse_args()
    if args.only == "memory":
        sizes = [1000, 10_000] if args.quick else [10_000, 100_000, 1_000_000]
        for r in memory(sizes):
            print(json.dumps(r), flush=True)
        return
    if args.only == "throughput":
        n_los, n_cap = (2000, 256) if args.quick else (20_000, 2000)
        for r in throughput("deep-impact-los", n_los, 200) + throughput(
            "lunar-skip-entry", n_cap, 32
        ):
            print(
                f"{r['scenario']:18s} {r['config']:38s} {r['runs']:>7,} runs {r['wall_s']:8.2f} s "
                f"{r['runs_per_s']:9,.0f} runs/s  x{r['vs_1_device']:.2f}  compile "
                f"{r['compile_s']:.1f} s  failed {r['failed']}",
                flush=True,
            )
        return
    out = run(args.quick)
    print(out["markdown"])
    for n in out["notes"]:
        print("note:", n)


if __name__ == "__main__":
    main()
