"""GPU acceptance in one call: gnc_jax's studies on a GPU through the CLI, with default settings.

    PYTHONPATH=. python benchmarks/gpu_acceptance.py --out DIR [--budget 400] [--quick]

Run from the repository's root on a machine with a GPU and JAX's GPU build (no install needed:
the CLI runs as ``python -m gnc_jax`` with the repository on ``PYTHONPATH``). Each part runs in
its own process with its own time limit, in order of value, and is skipped (saying so) when the
budget (``--budget`` seconds, default 400) no longer covers it; a part that runs out of time
keeps what it wrote. Results: ``DIR/acceptance.json`` (rewritten after every part) and a table
at the end of the output.

* ``status_cpu`` (in the background from the start, 4 host devices pinned to 4 cores, never
  touching the GPU): the first runs of ``deep-impact-los``, ``lunar-skip-entry`` and
  ``bennu-apn`` on the CPU (``--device cpu``), their outcomes saved for ``status_gpu``.
* ``planner``: for the four families (``deep-impact-los``, ``bennu-apn``, ``lunar-skip-entry``,
  ``phoenix-midcourse``) at their paper run counts and the sizes below, the planner's estimate
  on the GPU, its refusal (``max_hours`` 24) and the chunk it plans, without running anything.
* ``cli_*``: ``python -m gnc_jax run NAME --runs N --out TMP`` with default settings:
  ``deep-impact-los`` 1,000,000 runs, ``bennu-apn`` 2,000, ``lunar-skip-entry`` 100,000,
  ``bennu-apn`` 200,000. From ``summary.json``: compile time, the study's wall time and the
  writing of results apart (``compile_s``, ``wall_s``, ``write_s``), the chunk, the device; the
  process's whole wall and the CLI's result line besides.
* ``status_gpu``: the same runs as ``status_cpu`` on the GPU (``device="gpu"``); compared run for
  run: statuses equal, largest difference of every float outcome, and the summary statistics.
* ``sweep``: ``deep-impact-los`` 1,000,000 runs in chunks of 125k, 250k and 500k runs and at
  the default chunk (one process, each size compiled once), the GPU's running peak memory
  after each (the sizes grow, so each figure is its own): the default against the best.
* ``bench`` (if time is left): ``python -m benchmarks --device gpu``: the device suite with the
  numba peer on the same machine's CPU cores (``benchmarks/gpu.py``).

``--parts a,b``: only these parts (``status_cpu`` among them runs in the background as above).

``--quick`` runs every part at a few runs on whatever JAX finds (``auto``: a smoke test on a CPU).
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).resolve()
ROOT = HERE.parents[1]
LOS, BENNU, CAPSULE, MIDCOURSE = (
    "deep-impact-los",
    "bennu-apn",
    "lunar-skip-entry",
    "phoenix-midcourse",
)


def sizes(quick: bool) -> dict:
    if quick:
        return dict(
            cli=[(LOS, 64), (BENNU, 4), (CAPSULE, 8), (BENNU, 8)],
            status={LOS: 16, CAPSULE: 8, BENNU: 4},
            sweep=(LOS, 64, [16, 32, None]),
            device="auto",
        )
    return dict(
        cli=[(LOS, 1_000_000), (BENNU, 2_000), (CAPSULE, 100_000), (BENNU, 200_000)],
        status={LOS: 1024, CAPSULE: 512, BENNU: 64},
        sweep=(LOS, 1_000_000, [125_000, 250_000, 500_000, None]),
        device="gpu",
    )


# ---- parts, each in its own process ----------------------------------------------------------


def part_planner(args, plan) -> dict:
    import gnc_jax as gj
    from gnc_jax.backend import describe, select
    from gnc_jax.montecarlo import ANNOUNCE_S, MAX_HOURS
    from gnc_jax.planner import plan_chunk

    backend = select(plan["device"])
    rows = []
    cases = [(name, None) for name in (LOS, BENNU, CAPSULE, MIDCOURSE)] + [
        (name, runs) for name, runs in plan["cli"]
    ]
    for name, runs in cases:
        scenario = gj.load_scenario(name)
        runs = runs or scenario.runs
        cost = gj.estimate_cost(scenario, runs, device=backend)
        refused = cost.seconds is not None and cost.seconds > MAX_HOURS * 3600
        announce = cost.seconds is not None and cost.seconds > ANNOUNCE_S
        chunk = plan_chunk(
            scenario.system, runs, None, backend, backend.count, cost, announce, False
        )
        cpu = gj.estimate_cost(scenario, runs, device="cpu")
        rows.append(
            dict(
                scenario=name,
                runs=runs,
                estimate=str(cost),
                seconds=cost.seconds,
                refused=f"over {MAX_HOURS:g} h" if refused else None,
                chunk=chunk,
                chunks=-(-runs // chunk),
                cpu_estimate=str(cpu),
            )
        )
        print(f"{name} {runs}: {cost}; chunk {chunk}; refused: {refused}", flush=True)
    return dict(device=describe(backend), rows=rows)


def part_cli(args, plan, name, runs) -> dict:
    """One CLI study with default settings, its results written to a temporary directory."""
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "study"
        cmd = [sys.executable, "-m", "gnc_jax", "run", name, "--runs", str(runs), "--out", str(out)]
        if args.quick:
            cmd += ["--device", plan["device"]]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
        process_s = time.perf_counter() - t0
        summary = {}
        if (out / "summary.json").is_file():
            summary = json.loads((out / "summary.json").read_text())
    keep = ("compile_s", "wall_s", "write_s", "runs_per_s", "chunk_size", "failed", "device")
    return dict(
        command=" ".join(["gnc-jax"] + cmd[3:-2]),
        rc=proc.returncode,
        process_s=round(process_s, 2),
        result_line=(proc.stdout.splitlines() or [""])[0],
        stderr_tail=proc.stderr.strip().splitlines()[-3:],
        **{k: summary.get(k) for k in keep},
        statistics={k: v for k, v in summary.items() if k.endswith(("_m", "_mps", "_km"))},
    )


def _status_runs(args, plan, device, tag) -> dict:
    import numpy as np

    import gnc_jax as gj

    rows = {}
    for name, runs in plan["status"].items():
        study = gj.run_study(
            gj.load_scenario(name), runs=runs, seed=0, progress=False, device=device
        )
        np.savez(pathlib.Path(args.out) / f"status_{tag}_{name}.npz", **study.outcomes)
        summary = study.summary()
        rows[name] = dict(
            runs=runs,
            compile_s=round(study.compile_s, 2),
            wall_s=round(study.wall_s, 3),
            failed=summary["failed_by_status"],
            statistics={k: v for k, v in summary.items() if k.endswith(("_m", "_mps", "_km"))},
        )
        print(f"{tag} {name} {runs}: {study.wall_s:.2f} s", flush=True)
    return rows


def part_status_cpu(args, plan) -> dict:
    return _status_runs(args, plan, "cpu", "cpu")


def part_status_gpu(args, plan) -> dict:
    return _status_runs(args, plan, plan["device"], "gpu")


def part_sweep(args, plan) -> dict:
    import jax

    import gnc_jax as gj
    from gnc_jax.backend import select

    name, runs, chunks = plan["sweep"]
    device = select(plan["device"]).devices[0]
    scenario = gj.load_scenario(name)
    rows = []
    for chunk in chunks:
        study = gj.run_study(
            scenario, runs=runs, seed=0, chunk_size=chunk, progress=False, device=plan["device"]
        )
        stats = device.memory_stats() or {}
        rows.append(
            dict(
                chunk_asked=chunk,
                chunk=study.chunk_size,
                compile_s=round(study.compile_s, 2),
                wall_s=round(study.wall_s, 4),
                peak_mb=round(stats.get("peak_bytes_in_use", 0) / 1e6, 1) or None,
            )
        )
        print(f"sweep {name} {runs} chunk {study.chunk_size}: {study.wall_s:.3f} s", flush=True)
        jax.clear_caches()
    best = min(r["wall_s"] for r in rows)
    default = next(r for r in rows if r["chunk_asked"] is None)
    return dict(
        scenario=name,
        runs=runs,
        rows=rows,
        best_wall_s=best,
        default_over_best=round(default["wall_s"] / best, 3),
    )


def part_bench(args, plan) -> dict:
    cmd = [sys.executable, "-m", "benchmarks", "--device", plan["device"]]
    cmd += ["--out", str(pathlib.Path(args.out) / "bench" / "results_gpu.json")]
    if args.quick:
        cmd.append("--quick")
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
    return dict(rc=proc.returncode, tail=proc.stdout.strip().splitlines()[-20:])


PARTS = {
    "planner": (part_planner, 60),
    "cli_los": (lambda a, p: part_cli(a, p, *p["cli"][0]), 150),
    "cli_bennu_small": (lambda a, p: part_cli(a, p, *p["cli"][1]), 90),
    "cli_capsule": (lambda a, p: part_cli(a, p, *p["cli"][2]), 120),
    "cli_bennu_large": (lambda a, p: part_cli(a, p, *p["cli"][3]), 120),
    "status_gpu": (part_status_gpu, 120),
    "sweep": (part_sweep, 150),
    "bench": (part_bench, 150),
    "status_cpu": (part_status_cpu, 400),
}
QUICK_SLOWER = 5
"""``--quick`` parts may take this much longer (a small shared CPU compiles slowly)."""
MIN_START_S = {"bench": 120.0, "sweep": 60.0, "cli_bennu_large": 45.0}
"""A part starts only with this much budget left (else 20 s)."""


# ---- the driver ------------------------------------------------------------------------------


def _child(args, name: str, env=None, cores=None) -> subprocess.Popen:
    cmd = [sys.executable, str(HERE), "--part", name, "--out", args.out]
    if args.quick:
        cmd.append("--quick")
    preexec = (lambda: os.sched_setaffinity(0, cores)) if cores else None
    return subprocess.Popen(
        cmd, env=env, cwd=ROOT, start_new_session=True, preexec_fn=preexec, text=True
    )


def _finish(proc: subprocess.Popen, timeout: float) -> int:
    try:
        return proc.wait(timeout=max(timeout, 1.0))
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        proc.wait()
        return 124


def _nvidia_smi() -> str | None:
    query = "--query-gpu=name,memory.total,driver_version,clocks.max.sm,power.limit"
    try:
        proc = subprocess.run(
            ["nvidia-smi", query, "--format=csv,noheader"], capture_output=True, text=True
        )
    except OSError:
        return None
    return proc.stdout.strip() or None


def _part_result(args, name: str) -> dict | None:
    path = pathlib.Path(args.out) / "parts" / f"{name}.json"
    return json.loads(path.read_text()) if path.is_file() else None


def compare_statuses(args, plan) -> dict:
    """The GPU's and the CPU's outcomes of the same runs, run for run."""
    import numpy as np

    out = {}
    for name in plan["status"]:
        paths = [pathlib.Path(args.out) / f"status_{t}_{name}.npz" for t in ("cpu", "gpu")]
        if not all(p.is_file() for p in paths):
            out[name] = "missing: " + ", ".join(p.name for p in paths if not p.is_file())
            continue
        cpu, gpu = (dict(np.load(p)) for p in paths)
        same = cpu["status"] == gpu["status"]
        diffs = {}
        for k, x in cpu.items():
            if np.issubdtype(x.dtype, np.floating):
                both = np.isfinite(x) & np.isfinite(gpu[k])
                if both.any():
                    diffs[k] = float(np.max(np.abs(x[both] - gpu[k][both])))
            elif k != "status":
                diffs[k] = int(np.sum(x != gpu[k]))
        out[name] = dict(
            runs=int(same.size),
            statuses_equal=int(same.sum()),
            max_abs_diff=diffs,
        )
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True)
    p.add_argument("--budget", type=float, default=400.0, help="seconds for all parts")
    p.add_argument("--quick", action="store_true", help="a few runs each, on whatever JAX finds")
    p.add_argument("--parts", default=",".join(PARTS), help="the parts to run, comma-separated")
    p.add_argument("--part", default=None, help=argparse.SUPPRESS)  # a child's part
    args = p.parse_args()
    chosen = args.parts.split(",")
    if unknown := sorted(set(chosen) - set(PARTS)):
        p.error(f"--parts: unknown {', '.join(unknown)}; allowed: {', '.join(PARTS)}")
    plan = sizes(args.quick)
    pathlib.Path(args.out, "parts").mkdir(parents=True, exist_ok=True)
    sys.path.insert(0, str(ROOT))
    if args.part:
        result = PARTS[args.part][0](args, plan)
        pathlib.Path(args.out, "parts", f"{args.part}.json").write_text(
            json.dumps(result, indent=1, default=str)
        )
        return
    t0 = time.perf_counter()
    doc = dict(
        command=" ".join(sys.argv),
        quick=args.quick,
        budget_s=args.budget,
        cpu_count=os.cpu_count(),
        nvidia_smi=_nvidia_smi(),
        parts={},
    )
    report = pathlib.Path(args.out) / "acceptance.json"
    cores = sorted(os.sched_getaffinity(0))
    cpu_env = dict(os.environ, JAX_PLATFORMS="cpu", GNC_JAX_HOST_DEVICES="4")
    background = None
    if "status_cpu" in chosen:
        cpu_cores = set(cores[-4:]) if len(cores) > 8 else None
        background = _child(args, "status_cpu", cpu_env, cpu_cores)
    for name, (_, limit) in PARTS.items():
        if name == "status_cpu" or name not in chosen:
            continue
        limit *= QUICK_SLOWER if args.quick else 1
        left = args.budget - (time.perf_counter() - t0)
        if left < MIN_START_S.get(name, 20.0):
            doc["parts"][name] = dict(skipped=f"budget: {left:.0f} s left")
            print(f"## {name}: skipped ({left:.0f} s left)", flush=True)
            continue
        print(f"## {name} (limit {min(limit, left):.0f} s)", flush=True)
        start = time.perf_counter()
        rc = _finish(_child(args, name), min(limit, left))
        doc["parts"][name] = dict(
            rc=rc, part_s=round(time.perf_counter() - start, 1), result=_part_result(args, name)
        )
        report.write_text(json.dumps(doc, indent=1, default=str))
    if background is not None:
        rc = _finish(background, args.budget - (time.perf_counter() - t0))
        doc["parts"]["status_cpu"] = dict(rc=rc, result=_part_result(args, "status_cpu"))
        doc["statuses"] = compare_statuses(args, plan)
    doc["elapsed_s"] = round(time.perf_counter() - t0, 1)
    report.write_text(json.dumps(doc, indent=1, default=str))
    print_table(doc)
    print(f"wrote {report}", flush=True)


def print_table(doc) -> None:
    for name, part in doc["parts"].items():
        res = part.get("result") or {}
        if name.startswith("cli_") and res:
            print(
                f"{name}: {res['command']}: rc {res['rc']}, compile {res['compile_s']} s, study "
                f"{res['wall_s']} s, write {res['write_s']} s, chunk {res['chunk_size']}, "
                f"process {res['process_s']} s"
            )
        elif name == "planner" and res:
            for r in res["rows"]:
                print(f"planner: {r['scenario']} {r['runs']}: {r['estimate']}; chunk {r['chunk']}")
        elif name == "sweep" and res:
            print(f"sweep: {res['rows']}; default/best {res['default_over_best']}")
        else:
            print(f"{name}: rc {part.get('rc')} {part.get('skipped', '')}")
    for name, cmp in doc.get("statuses", {}).items():
        print(f"statuses {name}: {cmp}")


if __name__ == "__main__":
    main()
