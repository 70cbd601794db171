"""Loop variants on an accelerator: which change makes the deep closed loops shallower.

    python benchmarks/gpu_loops.py --out DIR [--quick] [--budget 220]

Each variant runs in its own process (XLA flags are read once per process) and times the same
studies through the public API, one chunk each, compile apart (``Study.compile_s``), seed 0:
``deep-impact-los`` 100,000 runs, ``bennu-apn`` 2,000 runs (91,200 strictly sequential steps:
latency-bound) and, in some variants, ``lunar-skip-entry`` 10,000 runs.

Variants:

* ``base``: the package as it is;
* ``nofence``: every ``computed_once`` fence inlined (on CPU a fence stops XLA from recomputing
  a guidance command inside each consumer loop; on a GPU a ``lax.cond`` may cost a predicate
  copy to the host per step);
* ``nofence_unroll4``: the same, and every innermost ``lax.scan`` unrolled 4 times;
* ``cmdbuf``: XLA's command buffers (CUDA graphs) extended to ``WHILE`` and ``CONDITIONAL``,
  so that a loop's iterations need no host round trip;
* ``nofence_cmdbuf``: both.

The first 64 runs of every study are compared with the ``base`` variant's: statuses equal and
the largest difference of every other outcome. Results: ``DIR/gpu_loops.json`` (rewritten after
every variant) and a table on stdout.

The variants above patch the package from outside (how its per-platform loop layout was
chosen; ``benchmarks/gpu_loops_h100.json``). ``--sweep "bennu-apn:2000:1,4,8,16 ..."`` times the
package's own :class:`~gnc_jax._numerics.LoopShape` instead, in this process: each item
``scenario:runs:shapes`` runs one chunk per shape against the system's GPU default; a shape is
an unroll, ``c`` after it carries the loop's vectors by component (``8c``) and ``a`` in arrays
(``8a``); without a letter the system's default layout is kept.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

HERE = pathlib.Path(__file__).resolve()
ROOT = HERE.parents[1]
FIRST = 64
CMDBUF = (
    "--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL"
)
VARIANTS = {
    "base": dict(fence=True, unroll=0, flags=""),
    "nofence": dict(fence=False, unroll=0, flags=""),
    "cmdbuf": dict(fence=True, unroll=0, flags=CMDBUF),
    "nofence_cmdbuf": dict(fence=False, unroll=0, flags=CMDBUF),
    "nofence_unroll4": dict(fence=False, unroll=4, flags=""),
}
FENCED_MODULES = (
    "gnc_jax.systems.intercept.navigation",
    "gnc_jax.systems.intercept.guidance_step",
    "gnc_jax.systems.impactor.step",
)


def studies(quick, variant):
    if quick:
        out = [("deep-impact-los", 32), ("bennu-apn", 8)]
        return out + ([("lunar-skip-entry", 8)] if variant in ("base", "cmdbuf") else [])
    out = [("deep-impact-los", 100_000), ("bennu-apn", 2_000)]
    return out + ([("lunar-skip-entry", 10_000)] if variant in ("base", "cmdbuf") else [])


def child(args):
    spec = VARIANTS[args.variant]
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(HERE.parent))
    if spec["unroll"]:
        from backend_probe import install_unroll

        install_unroll(spec["unroll"])
    import importlib

    import jax
    import numpy as np

    import gnc_jax as gj

    if not spec["fence"]:
        for name in FENCED_MODULES:
            mod = importlib.import_module(name)
            mod.computed_once = lambda fn, live, *a: fn(*a)
    rec = dict(
        variant=args.variant,
        flags=os.environ.get("XLA_FLAGS", ""),
        backend=jax.default_backend(),
        device=jax.devices()[0].device_kind,
        studies=[],
    )
    work = pathlib.Path(args.work)
    for name, runs in studies(args.quick, args.variant):
        scen = gj.load_scenario(name)
        t0 = time.perf_counter()
        try:
            st = gj.run_study(
                scen, runs=runs, seed=0, chunk_size=runs, progress=False, max_hours=1e6
            )
        except Exception as e:  # a failure is a result too
            rec["studies"].append(
                dict(scenario=name, runs=runs, error=f"{type(e).__name__}: {e}"[:400])
            )
            continue
        call = time.perf_counter() - t0
        t1 = time.perf_counter()
        st2 = gj.run_study(scen, runs=runs, seed=0, chunk_size=runs, progress=False, max_hours=1e6)
        call2 = time.perf_counter() - t1
        out = {k: np.asarray(v)[:FIRST] for k, v in st.outcomes.items()}
        np.savez(work / f"{args.variant}_{name}.npz", **out)
        status = np.asarray(st.status)
        rec["studies"].append(
            dict(
                scenario=name,
                runs=runs,
                compile_s=round(float(st.compile_s), 3),
                wall_s=round(float(st.wall_s), 4),
                wall2_s=round(float(st2.wall_s), 4),
                call_s=round(call, 3),
                call2_s=round(call2, 3),
                statuses={int(v): int(c) for v, c in zip(*np.unique(status, return_counts=True))},
            )
        )
        print(
            f"  [{args.variant}] {name} {runs}: compile {st.compile_s:.1f} s, "
            f"run {st.wall_s:.3f} / {st2.wall_s:.3f} s",
            flush=True,
        )
    pathlib.Path(args.json).write_text(json.dumps(rec, indent=1))


def sweep(items, out):
    """``items``: ``scenario:runs:s1,s2,...``; each study at the system's GPU default and at
    each shape (an unroll, ``c``/``a`` for by component/in arrays), one chunk, with the kernels
    of each loop body of its compiled program."""
    import jax
    import numpy as np
    from gpu_kernels import loop_bodies

    import gnc_jax as gj
    from gnc_jax import montecarlo
    from gnc_jax._numerics import for_platform, loop_shape, using_loop_shape

    rec = dict(backend=jax.default_backend(), default=list(loop_shape()), studies=[])
    for item in items:
        name, runs, tokens = item.split(":")
        runs, scen, first = int(runs), gj.load_scenario(name), None
        base = for_platform("gpu", scen.system)
        rec.setdefault("system_default", {})[name] = list(base)
        for u in [None] + tokens.split(","):
            shape = None
            if u is not None:
                layout = dict(c=dict(components=True), a=dict(components=False))
                shape = base._replace(unroll=int(u.rstrip("ac")), **layout.get(u[-1], {}))
            montecarlo._COMPILED.clear()
            with using_loop_shape(shape):
                kw = dict(runs=runs, seed=0, chunk_size=runs, progress=False, max_hours=1e6)
                st = gj.run_study(scen, **kw)
                st2 = gj.run_study(scen, **kw)
            kernels = [  # per loop body (trip count: kernels), the threefry hash's loop left out
                f"{b['trip']}: {sum(v for k, v in b['ops'].items() if not k.startswith('in-'))}"
                for c in montecarlo._COMPILED.values()
                for b in loop_bodies(c.as_text())
                if b["trip"] != 5
            ]
            status = np.asarray(st.status)
            row = dict(
                scenario=name,
                runs=runs,
                shape="default" if u is None else f"unroll{u}",
                loop_shape=list(shape or base),
                compile_s=round(float(st.compile_s), 3),
                wall_s=round(float(st.wall_s), 4),
                wall2_s=round(float(st2.wall_s), 4),
                kernels=kernels,
            )
            if first is None:
                first = st
            else:
                row["status_equal"] = bool(np.array_equal(status, np.asarray(first.status)))
                row["max_abs_diff"] = max(
                    float(np.nanmax(np.abs(np.asarray(v) - np.asarray(first.outcomes[k]))))
                    for k, v in st.outcomes.items()
                    if np.asarray(v).dtype.kind == "f"
                )
            rec["studies"].append(row)
            print(f"  sweep {row}", flush=True)
            (out / "gpu_sweep.json").write_text(json.dumps(rec, indent=1))


def compare(work, variant, name):
    import numpy as np

    a, b = work / f"base_{name}.npz", work / f"{variant}_{name}.npz"
    if not (a.is_file() and b.is_file()):
        return None
    a, b = np.load(a), np.load(b)
    diff = {}
    for k in a.files:
        x, y = np.asarray(a[k]), np.asarray(b[k])
        if k == "status":
            diff["status_equal"] = bool(np.array_equal(x, y))
        elif x.dtype.kind in "fc" and x.size:
            d = np.abs(x - y)
            diff[k] = float(np.nanmax(d)) if np.isfinite(d).any() else 0.0
    return diff


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--budget", type=float, default=220.0)
    p.add_argument("--variants", default=",".join(VARIANTS))
    p.add_argument("--child", default="")
    p.add_argument("--variant", default="")
    p.add_argument("--json", default="")
    p.add_argument("--work", default="/tmp/gpu_loops")
    p.add_argument("--sweep", nargs="*", default=None, help="scenario:runs:8,8c,8a,...")
    args = p.parse_args()
    if args.child:
        return child(args)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.sweep:
        sys.path[:0] = [str(ROOT), str(HERE.parent)]
        return sweep(args.sweep, out)
    work = pathlib.Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    result = dict(variants={})
    for v in args.variants.split(","):
        left = args.budget - (time.perf_counter() - t_start)
        if left < 30:
            result["variants"][v] = dict(skipped="time")
            continue
        env = dict(os.environ)
        if VARIANTS[v]["flags"]:
            env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " " + VARIANTS[v]["flags"]).strip()
        js = work / f"{v}.json"
        cmd = [
            sys.executable,
            str(HERE),
            "--out",
            str(out),
            "--child",
            "1",
            "--variant",
            v,
            "--json",
            str(js),
            "--work",
            str(work),
        ] + (["--quick"] if args.quick else [])
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, env=env, timeout=left, capture_output=True, text=True)
            tail = (proc.stdout + proc.stderr).strip().splitlines()[-6:]
        except subprocess.TimeoutExpired:
            tail = ["timed out"]
        print("\n".join(f"  {ln}" for ln in tail), flush=True)
        rec = json.loads(js.read_text()) if js.is_file() else dict(error=tail)
        rec["process_s"] = round(time.perf_counter() - t0, 1)
        for s in rec.get("studies", []):
            if v != "base":
                s["vs_base"] = compare(work, v, s["scenario"])
        result["variants"][v] = rec
        (out / "gpu_loops.json").write_text(json.dumps(result, indent=1))
    print(
        f"{'variant':18s} {'scenario':18s} {'runs':>8s} {'compile':>8s} {'run':>8s} "
        f"{'run2':>8s}  vs base"
    )
    for v, rec in result["variants"].items():
        for s in rec.get("studies", []):
            vs = s.get("vs_base") or {}
            worst = max((x for k, x in vs.items() if k != "status_equal"), default=0.0)
            print(
                f"{v:18s} {s['scenario']:18s} {s['runs']:>8,} {s.get('compile_s', 0):8.1f} "
                f"{s.get('wall_s', 0):8.3f} {s.get('wall2_s', 0):8.3f}  "
                f"{'status ' + str(vs.get('status_equal')) + f' max|d| {worst:.2e}' if vs else ''}"
                f"{s.get('error', '')}"
            )
    (out / "gpu_loops.json").write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
