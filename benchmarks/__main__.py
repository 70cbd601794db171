"""The whole benchmark suite in one run: ``python -m benchmarks [--quick] [--only a,b]``.

Each suite module (``run(quick) -> {"title", "rows", "markdown", "notes"}``) runs in its own
process, so that its peak memory is its own and one module's JIT caches or threads do not
colour the next; a module whose peer is not installed (the ``bench`` extra:
``pip install -e ".[bench]"``) is reported as skipped. Writes ``benchmarks/results.json``
(every row, the machine line, the commit) and ``benchmarks/RESULTS.md`` (the tables).
"""

import argparse
import json
import platform
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


def machine_line() -> str:
    import os

    import jax

    import gnc_jax  # noqa: F401  (host devices)

    return (
        f"{platform.machine()} {os.cpu_count()} cores, {len(jax.devices())} XLA host devices, "
        f"jax {jax.__version__}, CPython {platform.python_version()}"
    )


def run_module(name: str, module: str, quick: bool) -> dict:
    code = _CHILD.format(here=str(HERE), root=str(ROOT), module=module, quick=quick)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
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
    p.add_argument("--out", default=str(HERE / "results.json"))
    args = p.parse_args(argv)
    names = [n for n in args.only.split(",") if n] or list(SUITE)
    unknown = [n for n in names if n not in SUITE]
    if unknown:
        p.error(f"--only {','.join(unknown)}: unknown; allowed: {', '.join(SUITE)}")
    machine = machine_line()
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    print(f"# machine: {machine}; commit {commit}; quick={args.quick}", flush=True)
    results = {}
    for name in names:
        print(f"## {name} ...", flush=True)
        res = run_module(name, SUITE[name], args.quick)
        results[name] = res
        if res.get("skipped"):
            print(f"skipped ({res['skipped']})", flush=True)
        else:
            print(res["markdown"], flush=True)
            print(f"({res['seconds']:.0f} s, peak memory {res['peak_rss_mb']:.0f} MB)", flush=True)
    doc = dict(machine=machine, commit=commit, quick=args.quick, date=time.strftime("%Y-%m-%d"))
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
        results = {n: results.get(n) or earlier[n] for n in SUITE if n in results or n in earlier}
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
    (out.parent / "RESULTS.md").write_text("\n".join(md))
    print(f"wrote {args.out} and RESULTS.md", flush=True)


if __name__ == "__main__":
    main()
