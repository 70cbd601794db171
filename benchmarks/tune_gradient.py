"""One tuning gradient step per system family: forward mode (``jax.jacfwd``) against reverse
mode (``jax.grad``, through the system's :meth:`~gnc_jax.systems.AbstractSystem.reverse_mode`
loops) and the plain run, for a number of tunable parameters, on one core.

    python benchmarks/tune_gradient.py [--runs 256] [--only impactor,capsule]
        [--short] [--modes value,forward,reverse,reverse-any] [--params 0,2,16,32]

For each system with tunable gains, its example scenario (``--short``: with the system's
``test_overrides``) and all of its law's tunable gains: the relaxed objective of the tuner
(``gnc_jax.tuning``, the system's smooth objective) over ``--runs`` runs, its value, its
forward-mode gradient and its reverse-mode gradient (``reverse``: the tuner's, told which
gains are differentiated; ``reverse-any``: the system's reverse mode for a derivative with
respect to anything, which leaves nothing out of the reverse pass). ``--params P``: the
gradient with respect to ``P`` parameters, mapped into the law's gains (theta units) by a fixed
random matrix ``gains = theta_0 + A p`` (``A`` of shape gains x P, entries N(0, 1/P), seed 0):
the cost of a gradient in ``P`` parameters whatever form they take (a schedule's knots), on the
law's own closed loop (0: the gains themselves). Each (system, mode, P) runs in its own
process so that the peak resident memory (``ru_maxrss``) is its own; compile time apart, best
of 2 after the compilation, ``block_until_ready``; the compiled program's temp memory from
``memory_analysis``; the process's CPU time beside the wall time (on a shared machine the
CPU time of the one-core program is the steadier figure). The plain run (``value``) is the
baseline, printed as a ratio.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time


def measure(system_name, mode, runs, short, n_params):
    os.environ["GNC_JAX_HOST_DEVICES"] = "1"
    import jax
    import jax.numpy as jnp
    import numpy as np

    import gnc_jax as gj
    from gnc_jax import tuning
    from gnc_jax._numerics import using_loop_shape

    system = gj.get_system(system_name)
    scenario = gj.load_scenario(
        system.example, overrides=dict(system.test_overrides) if short else {}
    )
    law = system.law_name(scenario.config)
    params = [
        n
        for n in system.tunable_names()
        if n.startswith(f"guidance.{law}.") and not isinstance(scenario[n], list)
    ]  # the constant gains (a schedule's knots are --params's random map)
    problem = tuning.TuningProblem(
        scenario,
        tuning.resolve_gains(scenario, params),
        tuning.parse_objective(None, scenario),
        0,
    )
    theta0 = jnp.asarray(problem.param.theta([scenario[n] for n in params]))
    idx, valid = problem.padded(tuning.train_indices(0, runs, runs))
    temperature = problem.law_temperature
    # "reverse": the tuner's reverse mode, told which gains are differentiated; "reverse-any":
    # the system's reverse mode for a derivative of anything (no part of the pass left out)
    args = problem.args_for("reverse" if mode == "reverse" else "forward")
    if mode == "reverse-any":
        args = (problem.system.reverse_mode(args[0]),) + args[1:]
    if n_params:
        a = np.random.default_rng(0).standard_normal((len(params), n_params)) / n_params**0.5
        to_theta = lambda p: theta0 + jnp.asarray(a) @ p  # noqa: E731
        theta = jnp.zeros(n_params)
    else:
        to_theta, theta = (lambda p: p), theta0

    def f(p):
        gradient = mode.split("-")[0]
        return problem.smooth(args, to_theta(p), temperature, idx, valid, gradient)

    grad = jax.grad(f)
    fn = {"value": f, "forward": jax.jacfwd(f), "reverse": grad, "reverse-any": grad}[mode]
    t0 = time.perf_counter()
    with using_loop_shape(problem.loop_shape):  # the layout the tuner traces in
        compiled = jax.jit(fn).lower(theta).compile()
    compile_s = time.perf_counter() - t0
    best = cpu = float("inf")
    for _ in range(2):
        t0, c0 = time.perf_counter(), time.process_time()
        jax.block_until_ready(compiled(theta))
        best = min(best, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    stats = compiled.memory_analysis()
    return dict(
        system=system_name,
        scenario=scenario.name + (" (short)" if short else ""),
        gains=len(params),
        params=n_params or len(params),
        mode=mode,
        runs=runs,
        seconds=best,
        cpu_s=cpu,
        compile_s=compile_s,
        temp_mb=stats.temp_size_in_bytes / 1e6,
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3,
    )


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--runs", type=int, default=256)
    p.add_argument("--only", default="impactor,capsule")
    p.add_argument("--modes", default="value,forward,reverse")
    p.add_argument("--params", default="0", help="parameter counts (0: the law's gains)")
    p.add_argument("--short", action="store_true")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        name, mode, n = args.child
        print(json.dumps(measure(name, mode, args.runs, args.short, int(n))))
        return
    rows = []
    for name in args.only.split(","):
        for mode in args.modes.split(","):
            for n in [0] if mode == "value" else [int(x) for x in args.params.split(",")]:
                row = _child(name, mode, n, args)
                if row is None:
                    continue
                rows.append(row)
                base = next((r for r in rows if r["system"] == name and r["mode"] == "value"), None)
                ratio = (
                    f" ({row['seconds'] / base['seconds']:.1f}x value time, "
                    f"{row['cpu_s'] / base['cpu_s']:.1f}x its CPU time, "
                    f"{row['peak_rss_mb'] / base['peak_rss_mb']:.1f}x value peak RSS)"
                    if base
                    else ""
                )
                print(
                    f"{row['scenario']:<26} {row['params']:>2} params {mode:<11} {row['runs']} "
                    f"runs: {row['seconds']:.3g} s (CPU {row['cpu_s']:.3g} s){ratio}, "
                    f"compile {row['compile_s']:.0f} s, temp {row['temp_mb']:.1f} MB, "
                    f"peak RSS {row['peak_rss_mb']:.0f} MB",
                    flush=True,
                )


def _child(name, mode, n, args):
    cmd = [sys.executable, __file__, "--runs", str(args.runs), "--child", name, mode, str(n)]
    done = subprocess.run(cmd + (["--short"] if args.short else []), capture_output=True, text=True)
    if done.returncode:
        print(f"{name} {mode} {n}: failed: {done.stderr.strip().splitlines()[-1]}")
        return None
    return json.loads(done.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    main()
