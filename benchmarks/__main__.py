"""The whole benchmark suite in one run: ``python -m benchmarks [--quick] [--only a,b]``.

``python -m benchmarks --device gpu [--quick]`` runs the device suite instead
(``benchmarks/gpu.py``: gnc_jax on the GPU at up to 10^6 runs, GPU peak memory, compile apart,
against the suite's numba peer on the same machine's CPU cores in the same run) and writes
``benchmarks/results_gpu.json`` and ``RESULTS_GPU.md``; a machine without a GPU refuses in one
line naming the extra.

Each suite module (``run(quick) -> {"title", "rows", "markdown", "notes"}``) runs in its own
process, so that its peak memory is its own and one module's JIT caches or threads do not
colour the next; a module whose peer is not installed (the ``bench`` extra:
``pip install -e ".[bench]"``) is reported as skipped. Writes ``benchmarks/results.json``
(every row, the machine line, the commit) and ``benchmarks/RESULTS.md`` (the tables).
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

# Order: the package against the machine first, then each peer.
SUITE = {
    "closed_loops": "benchmarks.closed_loops",
    "capsule": "benchmarks.capsule",
    "numba_impactor": "benchmarks.peers.numba_impactor",
    "basilisk_impactor": "benchmarks.peers.basilisk_impactor",
    "propagation": "benchmarks.peers.propagation",
    "scale": "benchmarks.scale",
}

DEVICE_SUITE = {"gpu": "benchmarks.gpu"}

_CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, {here!r})
sys.path.insert(0, {root!r})
import importlib
t0 = time.perf_counter()
mod = importlib.import_module({module!r})
if not hasattr(mod, "run"):
    raise SystemExit("no run(quick) in " + {module!r})
out = mod.run(quick={quick!r})
out["seconds"] = time.perf_counter() - t0
out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print("@@RESULT@@" + json.dumps(out, default=float))
"""


def machine_line(device: str = "cpu") -> str:
    """The device's record in one line (:func:`gnc_jax.backend.describe_line`): platform,
    device kind and count, memory, jax/jaxlib (and CUDA) versions."""
    import gnc_jax  # noqa: F401  (host devices)
    from gnc_jax.backend import describe, describe_line, select

    return describe_line(describe(select(device)))


def run_module(name: str, module: str, quick: bool, device: str = "cpu") -> dict:
    import os

    code = _CHILD.format(here=str(HERE), root=str(ROOT), module=module, quick=quick)
    t0 = time.perf_counter()
    env = dict(os.environ, GNC_JAX_BENCH_DEVICE=device)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    marker = [ln for ln in proc.stdout.splitlines() if ln.startswith("@@RESULT@@")]
    if proc.returncode == 0 and marker:
        return json.loads(marker[-1][len("@@RESULT@@") :])
    tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["(no output)"]
    missing = "ModuleNotFoundError" in proc.stderr or "ImportError" in proc.stderr
    return dict(
        title=name,
        skipped=("not installed: " if missing else "failed: ") + tail[0],
        seconds=time.perf_counter() - t0,
        rows=[],
        markdown="",
        notes=[],
    )


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes (about a minute each)")
    p.add_argument("--only", default="", help="comma-separated subset of: " + ", ".join(SUITE))
    p.add_argument("--out", default=None, help="default: benchmarks/results[_DEVICE].json")
    p.add_argument(
        "--device",
        choices=("cpu", "gpu", "auto"),
        default="cpu",
        help="gpu/auto: the device suite (benchmarks/gpu.py) instead of the CPU suite",
    )
    args = p.parse_args(argv)
    suite = SUITE if args.device == "cpu" else DEVICE_SUITE
    args.out = args.out or str(HERE / ("results.json" if suite is SUITE else "results_gpu.json"))
    names = [n for n in args.only.split(",") if n] or list(suite)
    unknown = [n for n in names if n not in suite]
    if unknown:
        p.error(f"--only {','.join(unknown)}: unknown; allowed: {', '.join(suite)}")
    from gnc_jax.scenario import ScenarioError

    try:
        machine = machine_line(args.device)
    except ScenarioError as e:
        raise SystemExit(f"benchmarks: error: {e}") from None
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    print(f"# machine: {machine}; commit {commit}; quick={args.quick}", flush=True)
    results = {}
    for name in names:
        print(f"## {name} ...", flush=True)
        res = run_module(name, suite[name], args.quick, args.device)
        results[name] = res
        if res.get("skipped"):
            print(f"skipped ({res['skipped']})", flush=True)
        else:
            print(res["markdown"], flush=True)
            print(f"({res['seconds']:.0f} s, peak memory {res['peak_rss_mb']:.0f} MB)", flush=True)
    doc = dict(
        machine=machine,
        device=args.device,
        commit=commit,
        quick=args.quick,
        date=time.strftime("%Y-%m-%d"),
    )
    for res in results.values():
        res.update(machine=machine, commit=commit, quick=args.quick, date=doc["date"])
    out = Path(args.out)
    if args.only and out.is_file():  # a subset: the other modules keep their last results
        try:
            old = json.loads(out.read_text())
        except ValueError:
            old = {}
        earlier = old.get("results", {})
        for res in earlier.values():  # results written before sections carried their own
            for k in ("machine", "commit", "quick", "date"):
                res.setdefault(k, old.get(k))
        results = {n: results.get(n) or earlier[n] for n in suite if n in results or n in earlier}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(dict(doc, results=results), indent=1, default=float))
    md = [
        f"# Benchmark results\n\nMachine: {machine}. Commit {commit}, {doc['date']}"
        + (" (quick sizes)." if args.quick else ".")
        + " Written by `python -m benchmarks`"
        + (
            f" (this run: {args.only}; other sections say when they were measured)."
            if args.only
            else "."
        )
        + "\n"
    ]
    for name, res in results.items():
        md.append(f"## {res.get('title', name)}\n")
        if res.get("commit") and name not in names:
            md.append(
                f"Measured earlier: commit {res['commit']}, {res.get('date', '?')}"
                + (" (quick sizes)" if res.get("quick") else "")
                + ".\n"
            )
        if res.get("skipped"):
            md.append(f"Skipped: {res['skipped']}\n")
            continue
        md.append(res["markdown"] + "\n")
        md += [f"- {n}" for n in res.get("notes", [])]
        md.append(f"\n({res['seconds']:.0f} s; peak memory {res['peak_rss_mb']:.0f} MB)\n")
    md_name = "RESULTS.md" if suite is SUITE else "RESULTS_GPU.md"
    (out.parent / md_name).write_text("\n".join(md))
    print(f"wrote {args.out} and {md_name}", flush=True)


if __name__ == "__main__":
    main()
