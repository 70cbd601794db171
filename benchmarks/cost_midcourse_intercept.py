"""Measure ``step_seconds`` of the midcourse and intercept systems (their cost models:
``steps_per_run`` in ``gnc_jax/systems/{midcourse,intercept}.py``).

    python benchmarks/cost_midcourse_intercept.py [--runs 16]

For each system the first scenario calibrates: step_seconds = study wall time (compilation
excluded, best of 2) / (runs per device x steps per run). The other scenarios change what the
model scales with (loop lengths, solver, tolerance, iterations, sensitivity, fixes) and show the
estimate against the measured time as a ratio: the model is good to a factor of about 3. (The
intercept's CPU model is a throughput and a latency term, fitted by
``benchmarks/cost_calibration.py --fit``; its printed step_seconds is the one-term figure.)
"""

import argparse

import gnc_jax as gj
from gnc_jax.montecarlo import estimate_cost

CASES = {
    "intercept": [
        {},
        {"guidance.coast_s": 1000.0},
        {"navigation.image_interval_s": 5.0},
        {"navigation.model": "perfect", "guidance.dt_s": 0.5, "spacecraft.pulse_width_s": 0.05},
    ],
    "midcourse": [
        {},
        {"guidance.autonomous.iterations": 2},
        {"guidance.autonomous.sensitivity": "central_difference"},
        {"guidance.autonomous.sensitivity": "stm"},
        {"dynamics.solver": "dopri5"},
        {"navigation.fixes": 3, "navigation.interval_days": 20.0},
        {"dynamics.solver": "dopri5", "dynamics.rtol": 1e-10},
        {"dynamics.rtol": 1e-10},
    ],
}


def wall(scenario, runs):
    gj.run_study(scenario, runs=runs, seed=0, progress=False)  # compile
    return min(gj.run_study(scenario, runs=runs, seed=s, progress=False).wall_s for s in (1, 2))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=16)
    args = parser.parse_args()
    for name, cases in CASES.items():
        system = gj.get_system(name)
        calibrated = None
        for overrides in cases:
            scenario = gj.load_scenario(system.example, {**system.test_overrides, **overrides})
            cost = estimate_cost(scenario, args.runs)
            per_device = -(-args.runs // cost.n_devices)
            measured = wall(scenario, args.runs)
            seconds_per_step = measured / (per_device * cost.steps_per_run)
            if calibrated is None:
                calibrated = seconds_per_step
                print(f"{name}: step_seconds = {calibrated:.3g} s ({cost.n_devices} devices)")
            estimate = per_device * cost.steps_per_run * calibrated
            print(
                f"  {overrides or 'calibration'}: {cost.steps_per_run:.3g} steps/run, measured "
                f"{measured:.3g} s, estimated {estimate:.3g} s, ratio {estimate / measured:.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
