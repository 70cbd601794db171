"""Midcourse targeting throughput: dispersed Newton solutions/s, vmapped vs a Python loop.

    python benchmarks/midcourse.py [--sizes 1 10 100] [--methods autodiff ...]

For each sensitivity method the Newton targeter (`simulation.midcourse`, the E-238 d correction
of the packaged ``phoenix-midcourse`` transfer) is vmapped over dispersed initial states
(289 km, 0.577 m/s per axis), compiled ahead of time (compile time reported separately) and
timed with ``block_until_ready``, best of ``--repeats``, on one XLA device. The baseline is a
Python loop calling the jitted single-state solve, measured in the same process. The last
lines time the 100-run single-correction study the way ``gnc-jax run`` does (both cores,
after compilation; target <= 60 s).
"""

import argparse
import time

import jax
import jax.numpy as jnp
from _timing import best_of  # benchmarks/_timing.py

import gnc_jax as gj  # first: float64 and one XLA device per core
from gnc_jax.systems.midcourse import simulation as midcourse

SCENARIOS = {
    "autodiff": "phoenix-midcourse",
    "central_difference": "phoenix-midcourse-cd",
    "stm": "phoenix-midcourse-stm",
}


def dispersed_states(sim, n, seed=0):
    """n dispersed heliocentric states at the first fix (the simulator's initial draw)."""

    def draw(i, stream):
        return jax.random.normal(jax.random.fold_in(gj.run_key(seed, i), stream), (3,))

    index = jnp.arange(n)
    pos = sim.errors.position_m * jax.vmap(draw, in_axes=(0, None))(index, 0)
    vel = sim.errors.velocity_mps * jax.vmap(draw, in_axes=(0, None))(index, 1)
    x0 = jnp.concatenate([sim.r0_m, sim.v0_mps])
    return x0 + jnp.concatenate([pos, vel], axis=1)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[1, 10, 100])
    p.add_argument("--methods", nargs="+", default=list(SCENARIOS), choices=list(SCENARIOS))
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--loop-runs", type=int, default=10)
    args = p.parse_args()
    print(f"# {len(jax.devices())} XLA host devices; jax {jax.__version__}")
    for method in args.methods:
        scenario = gj.load_scenario(SCENARIOS[method])
        t0 = time.perf_counter()
        sim, law = gj.build(scenario)
        build_s = time.perf_counter() - t0

        def solve(x, sim=sim, law=law):
            return midcourse._solve_correction(sim, law, sim.t_first_fix_s, x)

        single = jax.jit(solve)
        states = dispersed_states(sim, max(args.sizes + [args.loop_runs]))
        t0 = time.perf_counter()
        jax.block_until_ready(single(states[0]))
        loop_compile = time.perf_counter() - t0
        loop = lambda f=single, x=states: [f(x[i]) for i in range(args.loop_runs)]
        loop_s = best_of(loop, 2)
        loop_rate = args.loop_runs / loop_s
        print(
            f"\n## {method} ({scenario.name}; build incl. nominal design {build_s:.1f} s)\n"
            f"python loop of jit(solve): compile {loop_compile:.2f} s, {loop_rate:.1f} solutions/s"
        )
        print("| N | compile (s) | run (s) | solutions/s | vs Python loop | converged |")
        print("|---:|---:|---:|---:|---:|---:|")
        batched = jax.jit(jax.vmap(solve))
        for n in args.sizes:
            xs = states[:n]
            t0 = time.perf_counter()
            compiled = batched.lower(xs).compile()
            compile_s = time.perf_counter() - t0
            run_s = best_of(lambda c=compiled, x=xs: c(x), args.repeats)
            converged = int(jnp.sum(compiled(xs).converged))
            rate = n / run_s
            print(
                f"| {n} | {compile_s:.2f} | {run_s:.3f} | {rate:,.1f} | "
                f"{rate / loop_rate:.2f}x | {converged}/{n} |"
            )
    print()
    for method in args.methods:
        scenario = gj.load_scenario(SCENARIOS[method])
        study = gj.run_study(scenario, runs=100, seed=0, progress=False)
        s = study.summary()
        print(
            f"gnc-jax run {scenario.name} --runs 100: compile {s['compile_s']:.2f} s, study "
            f"{s['wall_s']:.2f} s after compilation ({s['runs_per_s']:.0f} runs/s, "
            f"{study.n_devices} devices), goal met {s['goal_met']}/100; target <= 60 s"
        )
    print(f"machine: {s['machine']}")


if __name__ == "__main__":
    main()
