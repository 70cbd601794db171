"""Seed 004 APN intercept throughput: trajectories/s of a batch against a Python loop.

    python benchmarks/apn.py [--scenario bennu-apn] [--sizes 1 100 1000]

Each run is the full 25.5 h Table 2 arc closed at the 1 s guidance step (91 200 guidance
steps with a camera image and an EKF update each, then the coast). Each batch size is compiled
ahead of time (compile time reported separately), then timed with ``block_until_ready``, best of
``--repeats``. The baseline is a Python loop calling the jitted single-trajectory function run
by run, measured in the same process and printed as a ratio.
"""

import argparse
import time

import jax
import jax.numpy as jnp
from _timing import best_of  # benchmarks/_timing.py

import gnc_jax as gj  # first: float64 and one XLA device per core
from gnc_jax.montecarlo import SYSTEMS, batch_function


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="bennu-apn")
    p.add_argument("--sizes", type=int, nargs="+", default=[1, 100, 1000])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--loop-runs", type=int, default=4)
    args = p.parse_args()

    scenario = gj.load_scenario(args.scenario)
    system = SYSTEMS[scenario.kind]
    sim, law = system.build(scenario)
    seed = jnp.asarray(0, jnp.uint32)
    print(
        f"# {scenario.name}: {sim.n_images * sim.steps_per_image} guidance steps per run, "
        f"navigation {sim.nav_model}; {len(jax.devices())} XLA host devices; jax {jax.__version__}"
    )

    single = jax.jit(lambda s, l, k: system.simulate(s, l, k)[0])
    t0 = time.perf_counter()
    jax.block_until_ready(single(sim, law, gj.run_key(0, 0)))
    loop_compile = time.perf_counter() - t0
    keys = [gj.run_key(0, i) for i in range(args.loop_runs)]
    loop_s = best_of(lambda: [single(sim, law, k) for k in keys], 2)
    loop_rate = args.loop_runs / loop_s
    print(f"python loop of jit(simulate): compile {loop_compile:.2f} s, {loop_rate:.2f} traj/s")
    print()
    print("| N | devices | compile (s) | run (s) | trajectories/s | vs Python loop |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        for n_dev in sorted({1, len(jax.devices())}):
            if n % n_dev:
                continue
            fn, _ = batch_function(system, n_dev)
            idx = jnp.arange(n)
            t0 = time.perf_counter()
            compiled = fn.lower(sim, law, seed, idx).compile()
            compile_s = time.perf_counter() - t0
            repeats = args.repeats if n < 500 else 1
            run_s = best_of(lambda c=compiled, i=idx: c(sim, law, seed, i), repeats)
            rate = n / run_s
            print(
                f"| {n} | {n_dev} | {compile_s:.2f} | {run_s:.3f} | {rate:,.2f} | "
                f"{rate / loop_rate:.1f}x |"
            )


if __name__ == "__main__":
    main()
