"""Capsule closed-loop throughput and how close it runs to the bare integrator, in one run.

    python benchmarks/capsule.py [--sizes 1 10 100 1000 10000] [--repeats 2]

For each batch size the sharded, vmapped closed loop is compiled ahead of time (compile time
reported separately) and timed with ``block_until_ready``, best of ``--repeats``. Baselines
measured in the same process:

* a Python loop over the jitted single-trajectory function (trajectories/s ratio);
* the bare-integrator limit: a plain vmapped RK4 ``lax.scan`` of the same Cartesian truth
  dynamics (``entry_vector_field``: J2 gravity, US76 table, aerodynamics), as right-hand-side
  evaluations per second. The closed loop's evaluations are counted as the truth steps (4 per
  RK4 step over the whole fixed-length scan, as computed) plus the predictor's RK4 steps
  (4 each, from the per-run ``predictor_steps`` outcome); its rate over the bare rate is the
  fraction of the machine the guidance logic, the corrector and the bookkeeping leave to
  integration.

The last line times ``gnc-jax run lunar-skip-entry --runs 1000`` the way the CLI does it.
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from _timing import best_of, python_loop_rate, time_batch  # benchmarks/_timing.py

import gnc_jax as gj  # first: float64 and one XLA device per core
from gnc_jax.dynamics.entry import EntryArgs, entry_vector_field
from gnc_jax.integrate import rk4_step
from gnc_jax.simulation.capsule import dispersed_entry


def bare_rate(sim, n_runs, n_steps, repeats):
    """RHS evaluations/s of a vmapped RK4 scan of the truth dynamics, both devices."""
    keys = jax.vmap(lambda i: gj.run_key(0, i))(jnp.arange(n_runs))
    y0, vehicle, atm, _ = jax.vmap(lambda k: dispersed_entry(sim, k))(keys)
    bank = jnp.full((n_runs,), 1.0)

    def one(y, vehicle, atm, bank):
        args = EntryArgs(vehicle, sim.earth, atm, bank)

        def body(c, _):
            y, t = c
            return (rk4_step(entry_vector_field, t, y, sim.dt_s, args), t + sim.dt_s), None

        (y, _), _ = jax.lax.scan(body, (y, 0.0), None, length=n_steps)
        return y

    n_dev = len(jax.devices())
    fn = jax.pmap(jax.vmap(one)) if n_dev > 1 else jax.jit(jax.vmap(one))
    shard = lambda x: x.reshape((n_dev, -1) + x.shape[1:]) if n_dev > 1 else x  # noqa: E731
    data = jax.tree_util.tree_map(shard, (y0, vehicle, atm, bank))
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*data))
    compile_s = time.perf_counter() - t0
    run_s = best_of(lambda: fn(*data), repeats)
    return 4 * n_steps * n_runs / run_s, compile_s


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="lunar-skip-entry")
    p.add_argument("--sizes", type=int, nargs="+", default=[1, 10, 100, 1000, 10000])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--loop-runs", type=int, default=10)
    args = p.parse_args()

    scenario = gj.load_scenario(args.scenario)
    system = scenario.system
    sim, law = gj.build(scenario)
    truth_evals = 4 * sim.n_control * sim.substeps
    print(
        f"# {scenario.name}: {sim.n_control} control steps x {sim.substeps} truth RK4 steps "
        f"of {sim.dt_s} s per run; predictor RK4 dt {law.predictor_dt_s} s; "
        f"{len(jax.devices())} XLA host devices; jax {jax.__version__}"
    )

    bare, bare_compile = bare_rate(sim, 1000, sim.n_control * sim.substeps, args.repeats)
    print(f"bare vmapped RK4 scan of the truth dynamics (1000 runs): compile {bare_compile:.2f} s,")
    print(f"  {bare:.3g} right-hand-side evaluations/s")

    loop_compile, loop_rate = python_loop_rate(system, sim, law, args.loop_runs)
    print(f"python loop of jit(simulate): compile {loop_compile:.2f} s, {loop_rate:.2f} traj/s")
    print()
    print(
        "| N | devices | compile (s) | run (s) | trajectories/s | vs Python loop "
        "| RHS evals/s | of bare |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        n_dev = len(jax.devices()) if n % len(jax.devices()) == 0 else 1
        repeats = args.repeats if n <= 1000 else 1
        out, compile_s, run_s = time_batch(system, sim, law, n, n_dev, repeats)
        evals = n * truth_evals + 4 * float(np.sum(np.asarray(out.predictor_steps)))
        rate = n / run_s
        print(
            f"| {n} | {n_dev} | {compile_s:.2f} | {run_s:.3f} | {rate:,.1f} | "
            f"{rate / loop_rate:.1f}x | {evals / run_s:.3g} | {evals / run_s / bare:.0%} |"
        )
    print()
    study = gj.run_study(scenario, runs=1000, seed=0, progress=False)
    s = study.summary()
    print(
        f"gnc-jax run {scenario.name} --runs 1000: compile {s['compile_s']:.2f} s, "
        f"study wall {s['wall_s']:.2f} s after compilation ({s['runs_per_s']:.1f} runs/s, "
        f"{study.n_devices} devices); target <= 30 s"
    )
    print(f"machine: {s['machine']}")


if __name__ == "__main__":
    main()
