"""Seed 004 APN intercept throughput: trajectories/s of a batch against a Python loop.

    python benchmarks/apn.py [--scenario bennu-apn] [--sizes 1 100 1000]

Each run is the full 25.5 h Table 2 arc closed at the 1 s guidance step (91 200 guidance
steps with a camera image and an EKF update each, then the coast). Each batch size is compiled
ahead of time (compile time reported separately), then timed with ``block_until_ready``, best of
``--repeats``. The baseline is a Python loop calling the jitted single-trajectory function run
by run, measured in the same process and printed as a ratio.
"""

import argparse

import jax
from _timing import python_loop_rate, time_batch  # benchmarks/_timing.py

import gnc_jax as gj  # first: float64 and one XLA device per core


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="bennu-apn")
    p.add_argument("--sizes", type=int, nargs="+", default=[1, 100, 1000])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--loop-runs", type=int, default=4)
    args = p.parse_args()

    scenario = gj.load_scenario(args.scenario)
    system = scenario.system
    sim, law = gj.build(scenario)
    print(
        f"# {scenario.name}: {sim.n_images * sim.steps_per_image} guidance steps per run, "
        f"navigation {sim.nav_model}; {len(jax.devices())} XLA host devices; jax {jax.__version__}"
    )

    loop_compile, loop_rate = python_loop_rate(system, sim, law, args.loop_runs)
    print(f"python loop of jit(simulate): compile {loop_compile:.2f} s, {loop_rate:.2f} traj/s")
    print()
    print("| N | devices | compile (s) | run (s) | trajectories/s | vs Python loop |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        for n_dev in sorted({1, len(jax.devices())}):
            if n % n_dev:
                continue
            repeats = args.repeats if n < 500 else 1
            _, compile_s, run_s = time_batch(system, sim, law, n, n_dev, repeats)
            rate = n / run_s
            print(
                f"| {n} | {n_dev} | {compile_s:.2f} | {run_s:.3f} | {rate:,.2f} | "
                f"{rate / loop_rate:.1f}x |"
            )


if __name__ == "__main__":
    main()
