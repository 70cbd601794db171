"""Backend probe: how fast gnc_jax runs on a GPU and on a many-core CPU, and where the time goes.

    python benchmarks/backend_probe.py all --out DIR [--quick] [--budget 440]

One command measures, each part in its own Python process with its own time limit (a slow part
cannot eat the others; a part that runs out of time keeps what it measured so far), in order of
value (gpu_los, gpu_bennu, gpu_unroll4, cpu16, cpu1, numba, cpu16x, gpu_capsule, cpu8,
gpu_unroll16); a part whose turn comes after the budget (``--budget``, 440 s) is spent is
skipped and says so:

* ``gpu_los``: ``deep-impact-los`` on the accelerator: the default chunk size (the CPU-calibrated
  planner's) and chunks of 25k, 100k, 250k and 1M runs, at 10k, 100k and 1M runs.
* ``gpu_bennu``: ``bennu-apn`` (91,200 strictly sequential steps: latency-bound), 2,000 and
  20,000 runs (200,000 if time is left), one chunk each.
* ``gpu_unroll{k}``: ``bennu-apn`` 2,000 runs with ``jax.lax.scan`` patched (before gnc_jax is
  imported) to ``unroll=k`` for every *innermost* scan (one whose body starts no other
  ``jax.lax.scan``; unrolling an outer scan too would copy the inner one k times more). The
  unpatched ``gpu_bennu`` 2,000-run study is k = 1, the same program.
* ``gpu_capsule``: ``lunar-skip-entry`` 10,000 and 100,000 runs, one chunk each (1,024 runs at the
  default chunk if time is left).
* ``cpu{n}``: ``deep-impact-los`` on n XLA host devices of the CPU (``JAX_PLATFORMS=cpu``,
  ``GNC_JAX_HOST_DEVICES=n``), 2,000 runs per device in one chunk (the default planner's choice),
  n = 16, 1, 8, and 16 with ``--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1``
  (the device-count flag is put first: XLA ignores what follows the bare
  ``intra_op_parallelism_threads=1``, so gnc_jax's appended flag would be lost and the process
  would run on one device); per-core efficiency = throughput / (n x the 1-device throughput),
  best of the later calls.
* ``numba``: the suite's numba peer (``benchmarks/peers/numba_impactor.py --quick --sizes N
  --repeats 2``, all cores' threads) in the same run, as the CPU baseline: it times gnc_jax's
  ``run_study`` on all host devices against its kernel fed gnc_jax's normals and drawing its own.
* ``status_cpu`` (in the background from the start, pinned to two cores): the first 64 runs of
  each scenario on the CPU, compared run for run (status equal, largest difference of every other
  outcome) with the same runs of the accelerator's studies (a study's per-run outcomes do not
  depend on its chunk size); the unrolled studies are compared with the unpatched one likewise.

Every study goes through the public API only (``gj.load_scenario``, ``gj.run_study``), seed 0.
A study is called twice where time allows: the first call reports the compile time apart
(``Study.compile_s``, ahead-of-time compilation) and its run time (``Study.wall_s``); the second
reuses the executable (its run time is the steady figure). ``run_study`` returns numpy outcomes,
so every timed run has finished on the device (no extra ``block_until_ready`` is needed); the
call's whole wall (scenario build, compile, runs, transfer) is reported as ``call_s``. Peak
accelerator memory is ``jax.devices()[0].memory_stats()['peak_bytes_in_use']`` after each study:
the process's running peak, so the studies of a part run in increasing chunk size and a study's
figure is its own where it raised the peak (``new_peak``).

Results: ``DIR/probe.json`` (rewritten after every part) and a table at the end of the output.
``--quick`` runs every part at a few dozen runs on whatever JAX finds (a smoke test, on CPU).
On a machine with a GPU, e.g.::

    set -o pipefail; PYTHONUNBUFFERED=1 python benchmarks/backend_probe.py all --out $OUT \
        2>&1 | tee $OUT/log.txt
"""

import argparse
import contextlib
import inspect
import json
import os
import pathlib
import platform
import signal
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).resolve()
ROOT = HERE.parents[1]
FIRST = 64  # runs compared run for run between backends

LOS, BENNU, CAPSULE = "deep-impact-los", "bennu-apn", "lunar-skip-entry"


def plan(quick: bool) -> dict:
    """Sizes of every part: ``(runs, chunk, calls)`` items (chunk ``None``: the planner's
    default), required ones first, ``optional`` ones only while the part's time lasts."""
    if quick:
        return dict(
            los=[(16, None, 2), (32, 16, 2), (32, 32, 2), (64, 32, 1), (64, 64, 2)],
            los_optional=[(32, None, 1)],
            bennu=[(8, 8, 2), (16, 16, 1)],
            bennu_optional=[(32, 32, 1)],
            unroll_runs=8,
            unroll_ks=[4],
            capsule=[(8, 8, 2)],
            capsule_optional=[(16, 16, 2), (16, None, 1)],
            status_runs=8,
            cpu=[("cpu2", 2, 8, None), ("cpu1", 1, 4, None), ("cpu2x", 2, 8, "noeigen")],
            numba_runs=64,
        )
    return dict(
        los=[
            (10_000, None, 2),
            (100_000, 25_000, 2),
            (100_000, 100_000, 2),
            (1_000_000, 100_000, 1),
            (1_000_000, 250_000, 1),
            (1_000_000, 1_000_000, 2),
        ],
        los_optional=[(100_000, None, 1)],
        bennu=[(2_000, 2_000, 2), (20_000, 20_000, 1)],
        bennu_optional=[(200_000, 200_000, 1)],
        unroll_runs=2_000,
        unroll_ks=[4, 16],
        capsule=[(10_000, 10_000, 2)],
        capsule_optional=[(100_000, 100_000, 2), (1_024, None, 1)],
        status_runs=FIRST,
        cpu=[
            ("cpu16", 16, 32_000, None),
            ("cpu1", 1, 2_000, None),
            ("cpu16x", 16, 32_000, "noeigen"),
            ("cpu8", 8, 16_000, None),
        ],
        numba_runs=32_000,
    )


# ----------------------------------------------------------------------------------------------
# Inside a part's process


def install_unroll(k: int) -> dict:
    """Patch ``jax.lax.scan`` so that every innermost scan (whose body starts no other
    ``jax.lax.scan``) runs with ``unroll=k``; a caller's own ``unroll`` is kept. Found by tracing
    the body once abstractly (``jax.eval_shape``) before the real scan. Returns live counters."""
    import jax

    real = jax.lax.scan
    sig = inspect.signature(real)
    stats = dict(k=k, calls=0, unrolled=0, outer=0, probe_failed=0, _probing=0, _nested=0)

    def leaf(f, init, xs, length):
        def spec(x, drop=0):
            dtype = getattr(x, "dtype", None)
            dtype = jax.numpy.result_type(x) if dtype is None else dtype
            return jax.ShapeDtypeStruct(jax.numpy.shape(x)[drop:], dtype)

        carry = jax.tree_util.tree_map(spec, init)
        x = None if xs is None else jax.tree_util.tree_map(lambda a: spec(a, 1), xs)
        stats["_probing"] += 1
        nested0 = stats["_nested"]
        try:
            jax.eval_shape(f, carry, x)
        except Exception:
            stats["probe_failed"] += 1
            return False
        finally:
            stats["_probing"] -= 1
        return stats["_nested"] == nested0

    def scan(*args, **kwargs):
        bound = sig.bind(*args, **kwargs)
        bound.apply_defaults()
        a = bound.arguments
        if stats["_probing"]:
            stats["_nested"] += 1
            return real(*bound.args, **bound.kwargs)
        stats["calls"] += 1
        if a["unroll"] in (1, False) and leaf(a["f"], a["init"], a["xs"], a["length"]):
            a["unroll"] = k
            stats["unrolled"] += 1
        else:
            stats["outer"] += 1
        return real(*bound.args, **bound.kwargs)

    scan.__wrapped__ = real
    jax.lax.scan = scan
    return stats


class Part:
    """A part's results: written to its JSON file after every study (a part killed at its time
    limit keeps what it finished)."""

    def __init__(self, path, seconds):
        self.path = pathlib.Path(path)
        self.t0 = time.perf_counter()
        self.deadline = self.t0 + seconds
        self.data = dict(studies=[], notes=[])

    def left(self):
        return self.deadline - time.perf_counter()

    def write(self):
        self.data["elapsed_s"] = round(time.perf_counter() - self.t0, 2)
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.data, indent=1, default=str))
        tmp.replace(self.path)


def _jax_info(jax):
    import importlib.metadata as md

    d = jax.devices()[0]
    info = dict(
        jax=jax.__version__,
        backend=jax.default_backend(),
        device_count=jax.device_count(),
        device_kind=d.device_kind,
        platform=d.platform,
        XLA_FLAGS=os.environ.get("XLA_FLAGS", ""),
        JAX_PLATFORMS=os.environ.get("JAX_PLATFORMS", ""),
    )
    for pkg in ("jaxlib", "jax-cuda13-plugin", "jax-cuda12-plugin", "numba", "numpy"):
        with contextlib.suppress(md.PackageNotFoundError):
            info[pkg] = md.version(pkg)
    return info


def _peak_mb(jax):
    try:
        s = jax.devices()[0].memory_stats() or {}
    except Exception:
        s = {}
    if "peak_bytes_in_use" not in s:
        return None, None
    return s["peak_bytes_in_use"] / 2**20, s.get("bytes_limit", 0) / 2**20


def _status_counts(gj, status):
    import numpy as np

    values, counts = np.unique(status, return_counts=True)
    names = {}
    for v in values:
        try:
            names[int(v)] = gj.Status(int(v)).name
        except Exception:
            names[int(v)] = str(int(v))
    return {names[int(v)]: int(c) for v, c in zip(values, counts)}


def run_item(part, gj, jax, name, runs, chunk, tag=None, optional=False, save=None, calls=2):
    """One study of ``name``: ``runs`` runs, ``chunk`` runs per call (None: default), called
    ``calls`` times while the part's time lasts; appended to the part's results."""
    import numpy as np

    rec = dict(scenario=name, runs=runs, chunk_asked=chunk, tag=tag, calls=[])
    part.data["studies"].append(rec)
    params = inspect.signature(gj.run_study).parameters
    kw = dict(runs=runs, seed=0)
    if chunk is not None:
        kw["chunk_size"] = chunk
        if "progress" in params:
            kw["progress"] = False
    if "max_hours" in params:
        kw["max_hours"] = 1e6  # the CPU-calibrated estimate refuses GPU-sized studies
    scenario = gj.load_scenario(name)
    with contextlib.suppress(Exception):
        rec["estimate"] = str(gj.estimate_cost(scenario, runs, 1))
    peak0, _ = _peak_mb(jax)
    study = None
    for i in range(calls):
        if i and part.left() < 1.5 * rec["calls"][-1]["wall_s"] + 3:
            part.data["notes"].append(f"{name} {runs}/{chunk}: call {i + 1} skipped (time)")
            break
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            study = gj.run_study(scenario, **kw)
        except Exception as e:  # a refusal or a failure is a result too
            rec["error"] = f"{type(e).__name__}: {e}"[:500]
            print(f"  {name} runs={runs} chunk={chunk}: {rec['error']}", flush=True)
            part.write()
            return rec
        call_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
        wall = float(getattr(study, "wall_s", call_s))
        rec["calls"].append(
            dict(
                call_s=round(call_s, 4),
                compile_s=round(float(getattr(study, "compile_s", float("nan"))), 4),
                wall_s=round(wall, 4),
                cpu_s=round(cpu_s, 3),
                per_s=round(runs / wall, 1),
            )
        )
        rec["chunk"] = getattr(study, "chunk_size", None)
        rec["n_chunks"] = -(-runs // rec["chunk"]) if rec["chunk"] else None
        rec["devices"] = getattr(study, "n_devices", None)
        peak, limit = _peak_mb(jax)
        if peak is not None:
            rec["peak_mb"] = round(peak, 1)
            rec["new_peak"] = peak0 is None or peak > peak0 + 1
            rec["limit_mb"] = round(limit, 1)
        c = rec["calls"][-1]
        print(
            f"  {name:17s} runs={runs:>8,} chunk={rec['chunk']!s:>8} call {i + 1}: "
            f"compile {c['compile_s']:7.2f} s  run {c['wall_s']:8.3f} s  "
            f"{c['per_s']:>11,.0f} runs/s  call {c['call_s']:7.2f} s"
            + (f"  peak {rec['peak_mb']:,.0f} MB" if "peak_mb" in rec else ""),
            flush=True,
        )
        part.write()
    if study is not None:
        rec["statuses"] = _status_counts(gj, np.asarray(study.status))
        if save:
            out = study.outcomes
            np.savez(save, **{k: np.asarray(v)[:FIRST] for k, v in out.items()})
    part.write()
    return rec


def part_main(args):
    """One part, in this process (its environment set by the caller)."""
    stats = install_unroll(args.unroll) if args.unroll else None  # before gnc_jax is imported
    import jax

    import gnc_jax as gj

    p = plan(args.quick)
    part = Part(args.json, args.seconds)
    part.data.update(part=args.name, info=_jax_info(jax))
    print(f"[{args.name}] {json.dumps(part.data['info'])}", flush=True)
    part.write()
    work = pathlib.Path(args.work)
    name = args.name
    # Optional items start only with this many seconds left (each may compile).
    need = dict(los=45, bennu=60, capsule=40)
    for key, scen in (("los", LOS), ("bennu", BENNU), ("capsule", CAPSULE)):
        if name != f"gpu_{key}":
            continue
        for j, (runs, chunk, calls) in enumerate(p[key]):
            # the first runs of one study per scenario, for the comparison with the CPU
            first = (key == "los" and j == 2) or (key != "los" and j == 0)
            save = work / f"gpu_{key}.npz" if first else None
            run_item(part, gj, jax, scen, runs, chunk, save=save, calls=calls)
        for runs, chunk, calls in p[f"{key}_optional"]:
            if part.left() > need[key] or args.quick:
                run_item(part, gj, jax, scen, runs, chunk, optional=True, calls=calls)
            else:
                part.data["notes"].append(f"{scen} {runs}/{chunk}: skipped (time)")
    if name.startswith("gpu_unroll"):
        n = p["unroll_runs"]
        run_item(part, gj, jax, BENNU, n, n, tag=f"unroll={args.unroll}", save=work / f"{name}.npz")
        part.data["unroll"] = {k: v for k, v in stats.items() if not k.startswith("_")}
        print(f"  unroll patch: {part.data['unroll']}", flush=True)
    if name == "status_cpu":
        n = p["status_runs"]
        for scen in (LOS, BENNU, CAPSULE):
            short = {LOS: "los", BENNU: "bennu", CAPSULE: "capsule"}[scen]
            run_item(part, gj, jax, scen, n, n, save=work / f"cpu_{short}.npz", calls=1)
    elif name.startswith("cpu"):
        run_item(part, gj, jax, LOS, args.runs, None, calls=3)
    elif not name.startswith("gpu_"):
        raise SystemExit(f"unknown part {name}")
    part.write()


# ----------------------------------------------------------------------------------------------
# The driver


def _run_part(cmd, env, seconds, log_prefix, background=False, cpus=None):
    """Start a part as its own process group; return the Popen (background) or its exit code
    (124 when it ran out of time and was killed)."""
    preexec = None
    if cpus is not None and hasattr(os, "sched_setaffinity"):

        def preexec():
            with contextlib.suppress(OSError):
                os.sched_setaffinity(0, cpus)

    print(f"\n=== {log_prefix} (limit {seconds:.0f} s) ===", flush=True)
    proc = subprocess.Popen(cmd, env=env, start_new_session=True, preexec_fn=preexec)
    if background:
        return proc
    return _wait(proc, seconds)


def _wait(proc, seconds):
    try:
        return proc.wait(timeout=max(seconds, 1))
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        return 124


def _compare(a_path, b_path):
    """Run-for-run comparison of two saved first-run sets: equal statuses, and per float field
    the largest absolute and relative difference (where both are finite)."""
    import numpy as np

    if not (a_path.exists() and b_path.exists()):
        return None
    a, b = np.load(a_path), np.load(b_path)
    n = min(len(a["status"]), len(b["status"]))
    res = dict(runs=int(n), status_equal=int((a["status"][:n] == b["status"][:n]).sum()))
    fields = {}
    for k in a.files:
        if k == "status" or k not in b.files or a[k].dtype.kind != "f":
            continue
        x, y = a[k][:n].astype(float), b[k][:n].astype(float)
        both = np.isfinite(x) & np.isfinite(y)
        if not both.any():
            continue
        d = np.abs(x - y)[both]
        scale = np.maximum(np.abs(y[both]), 1e-300)
        fields[k] = dict(max_abs=float(d.max()), max_rel=float((d / scale).max()))
    res["fields"] = fields
    return res


def _machine():
    info = dict(
        python=sys.version.split()[0],
        platform=platform.platform(),
        cpu_count=os.cpu_count(),
        cpu=platform.processor() or platform.machine(),
    )
    with contextlib.suppress(OSError):
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
    with contextlib.suppress(Exception):
        q = "name,memory.total,driver_version,clocks.max.sm,power.limit"
        r = subprocess.run(
            ["nvidia-smi", f"--query-gpu={q}", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=20,
        )
        info["nvidia_smi"] = r.stdout.strip()
    return info


def _parse_markdown(text):
    rows, header = [], None
    for line in text.splitlines():
        if not line.startswith("|") or set(line) <= set("|-: "):
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        if header is None:
            header = cells
        else:
            rows.append(dict(zip(header, cells)))
    return rows


def all_main(args):
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    work = pathlib.Path(args.work or (out / "work" if args.quick else "/tmp/backend_probe"))
    work.mkdir(parents=True, exist_ok=True)
    p = plan(args.quick)
    t_start = time.perf_counter()
    result = dict(
        command=" ".join(sys.argv),
        quick=args.quick,
        budget_s=args.budget,
        machine=_machine(),
        parts={},
    )
    print(f"machine: {json.dumps(result['machine'])}", flush=True)
    ncpu = os.cpu_count() or 1
    base_env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    base_env["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT)] + [x for x in os.environ.get("PYTHONPATH", "").split(os.pathsep) if x]
    )
    base_env.pop("XLA_FLAGS", None)
    accel_env = dict(base_env, GNC_JAX_HOST_DEVICES="1")
    if args.accel:
        accel_env["JAX_PLATFORMS"] = args.accel
    cpu_env = dict(base_env, JAX_PLATFORMS="cpu")

    def save():
        result["elapsed_s"] = round(time.perf_counter() - t_start, 1)
        (out / "probe.json").write_text(json.dumps(result, indent=1, default=str))

    def left():
        return args.budget - (time.perf_counter() - t_start)

    def part_cmd(name, seconds, **extra):
        cmd = [sys.executable, str(HERE), "part", name, "--json", str(work / f"{name}.json")]
        cmd += ["--seconds", str(int(seconds)), "--work", str(work)]
        cmd += ["--quick"] if args.quick else []
        for k, v in extra.items():
            cmd += [f"--{k}", str(v)]
        return cmd

    def collect(name, rc, t0):
        path = work / f"{name}.json"
        data = json.loads(path.read_text()) if path.exists() else {}
        data.update(rc=rc, part_wall_s=round(time.perf_counter() - t0, 1))
        result["parts"][name] = data
        save()

    def part(name, seconds, env, **extra):
        seconds = min(seconds, left() - 5)
        if seconds < 15:
            result["parts"][name] = dict(skipped="no time left in the budget")
            print(f"\n=== {name}: skipped (budget) ===", flush=True)
            save()
            return
        t0 = time.perf_counter()
        rc = _run_part(part_cmd(name, seconds - 5, **extra), env, seconds, name)
        collect(name, rc, t0)

    # The CPU's first runs, in the background on two cores, while the accelerator works.
    status_cpus = {ncpu - 2, ncpu - 1} if ncpu >= 4 else None
    t_status = time.perf_counter()
    status_env = dict(cpu_env, GNC_JAX_HOST_DEVICES="2" if status_cpus else "1")
    status_proc = _run_part(
        part_cmd("status_cpu", 240),
        status_env,
        240,
        "status_cpu (background)",
        background=True,
        cpus=status_cpus,
    )

    quick = args.quick  # quick: generous limits (the smoke test compiles on 2 cores)
    ks = p["unroll_ks"]
    cpu_parts = {name: (n, runs, variant) for name, n, runs, variant in p["cpu"]}

    def cpu_part(name, seconds):
        n, runs, variant = cpu_parts[name]
        env = dict(cpu_env, GNC_JAX_HOST_DEVICES=str(n))
        if variant == "noeigen":  # the device count first: XLA ignores flags after 'intra_op...'
            env["XLA_FLAGS"] = (
                f"--xla_force_host_platform_device_count={n} "
                "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
            )
        part(name, 200 if quick else seconds, env, runs=runs)

    # In order of value; each part's limit is also cut to what is left of the budget.
    part("gpu_los", 300 if quick else 130, accel_env)
    part("gpu_bennu", 200 if quick else 65, accel_env)
    part(f"gpu_unroll{ks[0]}", 200 if quick else 50, accel_env, unroll=ks[0])

    rc = _wait(status_proc, max(250 - (time.perf_counter() - t_status), 1))
    collect("status_cpu", rc, t_status)

    names = list(cpu_parts)
    cpu_part(names[0], 30)  # all cores
    cpu_part(names[1], 25)  # one device

    # The suite's numba peer, all cores' threads, gnc_jax on all host devices beside it.
    seconds = min(400 if quick else 130, left() - 5)
    if seconds >= 30:
        env = dict(cpu_env, GNC_JAX_HOST_DEVICES=str(ncpu), NUMBA_NUM_THREADS=str(ncpu))
        cmd = [sys.executable, str(ROOT / "benchmarks/peers/numba_impactor.py"), "--quick"]
        cmd += ["--sizes", str(p["numba_runs"]), "--repeats", "2"]
        print(f"\n=== numba peer (limit {seconds:.0f} s): {' '.join(cmd[1:])} ===", flush=True)
        t0 = time.perf_counter()
        deadline = t0 + seconds
        proc = subprocess.Popen(
            cmd, env=env, start_new_session=True, stdout=subprocess.PIPE, text=True
        )
        lines = []
        try:
            for line in proc.stdout:  # echoed as it comes
                print(line, end="", flush=True)
                lines.append(line)
                if time.perf_counter() > deadline:
                    break
        finally:
            rc = _wait(proc, max(deadline - time.perf_counter(), 1))
        text = "".join(lines)
        result["parts"]["numba"] = dict(
            rc=rc,
            threads=ncpu,
            part_wall_s=round(time.perf_counter() - t0, 1),
            rows=_parse_markdown(text),
            notes=[x[2:].strip() for x in text.splitlines() if x.startswith("- ")],
        )
    else:
        result["parts"]["numba"] = dict(skipped="no time left in the budget")
    save()

    for name in names[2:3]:
        cpu_part(name, 25)  # all cores, XLA's thread settings
    part("gpu_capsule", 200 if quick else 70, accel_env)
    for name in names[3:]:
        cpu_part(name, 25)  # half the cores
    for k in ks[1:]:
        part(f"gpu_unroll{k}", 200 if quick else 60, accel_env, unroll=k)

    # Run-for-run comparisons.
    cmp = {}
    for short in ("los", "bennu", "capsule"):
        cmp[f"{short}: accelerator vs cpu"] = _compare(
            work / f"gpu_{short}.npz", work / f"cpu_{short}.npz"
        )
    for k in ks:
        cmp[f"bennu: unroll={k} vs unroll=1"] = _compare(
            work / f"gpu_unroll{k}.npz", work / "gpu_bennu.npz"
        )
    result["compare"] = cmp
    save()
    print_table(result)
    save()


def print_table(result):
    """The compact table of every figure."""
    print("\n# Backend probe: every study (first call: compile + run; later calls: run)\n")
    print(
        "| part | scenario | runs | chunk | chunks | compile s | run s (1st) | run s (best later)"
        " | runs/s | peak MB | devices |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    cpu1 = None
    for name, data in result["parts"].items():
        for st in data.get("studies", []):
            calls = st.get("calls", [])
            if not calls:
                err = st.get("error", "no call finished")
                print(
                    f"| {name} | {st['scenario']} | {st['runs']:,} | {st['chunk_asked']} | | | "
                    f"| | {err[:80]} | | |"
                )
                continue
            later = [c["wall_s"] for c in calls[1:]]
            best = min(later) if later else calls[0]["wall_s"]
            rate = st["runs"] / best
            if name == "cpu1":
                cpu1 = rate
            st["best_wall_s"], st["best_per_s"] = best, rate
            peak = st.get("peak_mb")
            peak_s = "" if peak is None else f"{peak:,.0f}" + ("" if st.get("new_peak") else " (≤)")
            print(
                f"| {name} | {st['scenario']} | {st['runs']:,} | {st.get('chunk')} | "
                f"{st.get('n_chunks')} | {calls[0]['compile_s']:.2f} | {calls[0]['wall_s']:.3f} | "
                + (f"{min(later):.3f}" if later else "—")
                + f" | {rate:,.0f} | {peak_s} | {st.get('devices')} |"
            )
        if data.get("rc") not in (0, None):
            why = " (timed out)" if data.get("rc") == 124 else ""
            print(f"| {name} | exit {data.get('rc')}{why} | | | | | | | | | |")
        if "skipped" in data:
            print(f"| {name} | skipped: {data['skipped']} | | | | | | | | | |")
    if cpu1:
        print("\n# CPU host devices (deep-impact-los): per-core efficiency vs 1 device\n")
        print("| part | devices | XLA_FLAGS | runs | runs/s | per device | efficiency |")
        print("|---|---|---|---|---|---|---|")
        for name, data in result["parts"].items():
            if not name.startswith("cpu") or not data.get("studies"):
                continue
            st = data["studies"][0]
            if "best_per_s" not in st:
                continue
            n = data["info"]["device_count"]
            flags = data["info"].get("XLA_FLAGS", "")
            flags = flags.replace("--xla_force_host_platform_device_count", "n")
            eff = st["best_per_s"] / (n * cpu1)
            data["efficiency"] = eff
            print(
                f"| {name} | {n} | {flags} | {st['runs']:,} | {st['best_per_s']:,.0f} | "
                f"{st['best_per_s'] / n:,.0f} | {eff:.0%} |"
            )
    numba = result["parts"].get("numba", {})
    if numba.get("rows"):
        print("\n# numba peer (same machine, same run)\n")
        print("| " + " | ".join(numba["rows"][0]) + " |")
        print("|" + "---|" * len(numba["rows"][0]))
        for r in numba["rows"]:
            print("| " + " | ".join(r.values()) + " |")
        for n in numba.get("notes", [])[:3]:
            print(f"- {n}")
        own = next((r for r in numba["rows"] if r.get("name", "").startswith("numba own")), None)
        fed = next((r for r in numba["rows"] if r.get("name", "").startswith("numba fed")), None)
        base = {}
        for label, row in (("own draws", own), ("fed", fed)):
            with contextlib.suppress(Exception):
                base[label] = float(row["per_s"].replace(",", ""))
        if base:
            print("\n# Throughput over the numba peer's (same machine, same run)\n")
            for name, data in result["parts"].items():
                for st in data.get("studies", []):
                    if st.get("scenario") != LOS or "best_per_s" not in st:
                        continue
                    r = ", ".join(f"{st['best_per_s'] / v:.2f}x {k}" for k, v in base.items())
                    print(f"- {name} {st['runs']:,} runs, chunk {st.get('chunk')}: {r}")
    print("\n# Run-for-run comparisons (first runs, seed 0)\n")
    for k, v in result.get("compare", {}).items():
        if v is None:
            print(f"- {k}: not available")
            continue
        worst = sorted(v["fields"].items(), key=lambda kv: -kv[1]["max_rel"])[:3]
        w = ", ".join(f"{f} |d|≤{d['max_abs']:.3g} (rel {d['max_rel']:.2g})" for f, d in worst)
        print(f"- {k}: statuses equal {v['status_equal']}/{v['runs']}; largest: {w}")
    for name, data in result["parts"].items():
        if "unroll" in data:
            print(f"- {name} patch: {data['unroll']}")
    print(f"\nprobe elapsed {result.get('elapsed_s')} s of a {result['budget_s']} s budget")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("all", help="every part, each in its own process (the benchmark)")
    a.add_argument("--out", required=True, help="folder for probe.json")
    a.add_argument("--work", default=None, help="scratch folder (default /tmp/backend_probe)")
    a.add_argument("--quick", action="store_true", help="a few dozen runs each (smoke test)")
    a.add_argument("--budget", type=float, default=440.0, help="seconds for all parts")
    a.add_argument(
        "--accel",
        default=None,
        help="JAX_PLATFORMS of the accelerator parts (default: cuda; --quick: JAX's choice)",
    )
    q = sub.add_parser("part", help="one part in this process (used by 'all')")
    q.add_argument("name")
    q.add_argument("--json", required=True)
    q.add_argument("--work", required=True)
    q.add_argument("--seconds", type=float, default=120.0)
    q.add_argument("--quick", action="store_true")
    q.add_argument("--unroll", type=int, default=0)
    q.add_argument("--runs", type=int, default=0)
    args = ap.parse_args()
    if args.cmd == "all":
        if args.accel is None and not args.quick:
            args.accel = "cuda"
        all_main(args)
    else:
        part_main(args)


if __name__ == "__main__":
    main()
