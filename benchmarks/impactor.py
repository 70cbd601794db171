"""Impactor closed-loop throughput: trajectories/s against a Python loop, measured in one run.

    python benchmarks/impactor.py [--scenario deep-impact-los] [--sizes 1 100 1000 10000]

Each batch size is compiled ahead of time (compile time reported separately), then timed with
``block_until_ready``, best of ``--repeats``. The baseline is a Python loop calling the jitted
single-trajectory function run by run, measured in the same process. The last line times the
full 2000-run study the way ``gnc-jax run`` does (both cores, after compilation).
"""

import argparse

import jax
from _timing import python_loop_rate, time_batch  # benchmarks/_timing.py

import gnc_jax as gj  # first: float64 and one XLA device per core


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="deep-impact-los")
    p.add_argument("--sizes", type=int, nargs="+", default=[1, 100, 1000, 10000])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--loop-runs", type=int, default=20)
    args = p.parse_args()

    scenario = gj.load_scenario(args.scenario)
    system = scenario.system
    sim, law = gj.build(scenario)
    print(
        f"# {scenario.name}: {sim.n_images * sim.steps_per_image} control steps per run; "
        f"{len(jax.devices())} XLA host devices; jax {jax.__version__}"
    )

    loop_compile, loop_rate = python_loop_rate(system, sim, law, args.loop_runs)
    print(f"python loop of jit(simulate): compile {loop_compile:.2f} s, {loop_rate:.1f} traj/s")
    print()
    print("| N | devices | compile (s) | run (s) | trajectories/s | vs Python loop |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in args.sizes:
        for n_dev in sorted({1, len(jax.devices())}):
            if n % n_dev:
                continue
            repeats = args.repeats if n < 5000 else 1
            _, compile_s, run_s = time_batch(system, sim, law, n, n_dev, repeats)
            rate = n / run_s
            print(
                f"| {n} | {n_dev} | {compile_s:.2f} | {run_s:.3f} | {rate:,.0f} | "
                f"{rate / loop_rate:.0f}x |"
            )
    print()
    study = gj.run_study(scenario, runs=2000, seed=0, progress=False)
    s = study.summary()
    print(
        f"gnc-jax run {scenario.name} --runs 2000: compile {s['compile_s']:.2f} s, "
        f"study wall {s['wall_s']:.2f} s after compilation ({s['runs_per_s']:.0f} runs/s, "
        f"{study.n_devices} devices); target <= 10 s"
    )
    print(f"machine: {s['machine']}")


if __name__ == "__main__":
    main()
