"""One tuning gradient step per system family: forward mode (``jax.jacfwd``, the tuner's
default) against reverse mode (``jax.grad``) and the plain forward run, on one core.

    python benchmarks/tune_gradient.py [--runs 256] [--only impactor,intercept,capsule]
        [--short] [--modes value,forward,reverse]

For each system with tunable gains, its example scenario (``--short``: with the system's
``test_overrides``) and all of its law's tunable gains: the relaxed objective of the tuner
(``gnc_jax.tuning``, the system's smooth objective) over ``--runs`` runs, its value, its
forward-mode gradient and its reverse-mode gradient. Each mode runs in its own process so that
the peak resident memory (``ru_maxrss``) is its own; compile time apart, best of 2 after the
compilation, ``block_until_ready``; the compiled program's temp memory from
``memory_analysis``. The capsule's flight is a ``while_loop``: reverse mode does not apply.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time


def measure(system_name, mode, runs, short):
    os.environ["GNC_JAX_HOST_DEVICES"] = "1"
    import jax
    import jax.numpy as jnp

    import gnc_jax as gj
    from gnc_jax import tuning

    system = gj.get_system(system_name)
    scenario = gj.load_scenario(
        system.example, overrides=dict(system.test_overrides) if short else {}
    )
    law = system.law_name(scenario.config)
    params = [n for n in system.tunable_names() if n.startswith(f"guidance.{law}.")]
    problem = tuning.TuningProblem(
        scenario,
        tuning.resolve_gains(scenario, params),
        tuning.parse_objective(None, scenario),
        0,
    )
    theta = jnp.asarray(problem.param.theta([scenario[n] for n in params]))
    idx, valid = problem.padded(tuning.train_indices(0, runs, runs))
    temperature = problem.law_temperature

    def f(th):
        return problem.smooth(problem.args, th, temperature, idx, valid)

    fn = {"value": f, "forward": jax.jacfwd(f), "reverse": jax.grad(f)}[mode]
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(theta).compile()
    compile_s = time.perf_counter() - t0
    best = float("inf")
    for _ in range(2):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(theta))
        best = min(best, time.perf_counter() - t0)
    stats = compiled.memory_analysis()
    return dict(
        system=system_name,
        scenario=scenario.name + (" (short)" if short else ""),
        gains=len(params),
        mode=mode,
        runs=runs,
        seconds=best,
        compile_s=compile_s,
        temp_mb=stats.temp_size_in_bytes / 1e6,
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3,
    )


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--runs", type=int, default=256)
    p.add_argument("--only", default="impactor,intercept,capsule")
    p.add_argument("--modes", default="value,forward,reverse")
    p.add_argument("--short", action="store_true")
    p.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(measure(*args.child, args.runs, args.short)))
        return
    rows = []
    for name in args.only.split(","):
        for mode in args.modes.split(","):
            if name == "capsule" and mode == "reverse":
                continue  # while_loop: not reverse-differentiable
            cmd = [sys.executable, __file__, "--runs", str(args.runs), "--child", name, mode]
            done = subprocess.run(
                cmd + (["--short"] if args.short else []), capture_output=True, text=True
            )
            if done.returncode:
                print(f"{name} {mode}: failed: {done.stderr.strip().splitlines()[-1]}")
                continue
            row = json.loads(done.stdout.strip().splitlines()[-1])
            rows.append(row)
            base = next(
                (r["seconds"] for r in rows if r["system"] == name and r["mode"] == "value"), None
            )
            ratio = f" ({row['seconds'] / base:.1f}x value)" if base else ""
            print(
                f"{row['scenario']:<26} {row['gains']} gains {mode:<8} {row['runs']} runs: "
                f"{row['seconds']:.3g} s{ratio}, compile {row['compile_s']:.0f} s, temp "
                f"{row['temp_mb']:.1f} MB, peak RSS {row['peak_rss_mb']:.0f} MB",
                flush=True,
            )


if __name__ == "__main__":
    main()
