"""Calibrate the capsule cost model: measured study wall time against steps_per_run.

    GNC_JAX_CACHE=/tmp/capsule_cache python benchmarks/capsule_cost.py [--runs 256]

For the paper scenario and off-nominal variants, prints the reference-design time (``build``:
a cache miss designs; a hit only loads), the compile time, the study's wall time after
compilation, ``CapsuleSystem.steps_per_run`` and the step time it implies
(wall x devices / runs / steps), and the ratio of the current estimate (``estimate_cost``,
from the capsule's CPU ``StepCost``) to the measured wall time.
"""

import argparse
import time

import gnc_jax as gj  # first: float64 and one XLA device per core
from gnc_jax.montecarlo import build, estimate_cost

CASES = {
    "paper": [],
    "range 5000 km": ["entry.range_km=5000"],
    "range 2500 km": ["entry.range_km=2500"],
    "fpa -6.5 deg": ["entry.fpa_deg=-6.5"],
}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=256)
    p.add_argument("--cases", nargs="+", default=list(CASES))
    args = p.parse_args()
    for name in args.cases:
        scenario = gj.load_scenario("lunar-skip-entry", CASES[name])
        t0 = time.perf_counter()
        build(scenario)
        design_s = time.perf_counter() - t0
        study = gj.run_study(scenario, runs=args.runs, progress=False)
        cost = estimate_cost(scenario, args.runs)
        per_device = -(-args.runs // study.n_devices)
        step_s = study.wall_s / (per_device * cost.steps_per_run)
        print(
            f"{name:>14}: build {design_s:6.1f} s, compile {study.compile_s:5.1f} s, "
            f"{args.runs} runs {study.wall_s:6.2f} s, failed {int((~study.ok).sum())}, "
            f"{cost.steps_per_run:8.0f} steps/run -> {step_s:.3g} s/step; "
            f"estimate {cost.seconds:.3g} s = {cost.seconds / study.wall_s:.2f} x measured",
            flush=True,
        )


if __name__ == "__main__":
    main()
