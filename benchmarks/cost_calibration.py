"""How good is the cost estimate that ``run_study`` checks before it builds or compiles anything?

For the packaged scenarios and off-nominal variations of each system, runs a study and prints
the estimate (:func:`gnc_jax.estimate_cost`: the system's ``steps_per_run`` x its measured
``step_seconds``) next to the measured wall time after compilation, and their ratio. The
systems' ``step_seconds`` constants come from this script; the estimate is meant to be within
a factor of about 3, enough to refuse a runaway study and to size progress chunks.

    python benchmarks/cost_calibration.py [--system impactor] [--scale 1.0]
"""

import argparse

import gnc_jax as gj
from gnc_jax.montecarlo import estimate_cost

CASES = {
    "impactor": [
        ("deep-impact-los", 1000, {}),
        ("deep-impact-los", 400, {"guidance.dt_s": 0.1}),
        ("deep-impact-los", 1000, {"camera.image_interval_s": 60.0}),
        ("deep-impact-predictive", 1000, {}),
        ("deep-impact-los", 40, {"navigation.measurement": "image"}),
        ("autonav-predictive", 40, {}),
    ],
    "capsule": [
        ("lunar-skip-entry", 20, {}),
        ("lunar-skip-entry", 20, {"entry.range_km": 3000.0}),
        ("lunar-skip-entry", 20, {"simulation.dt_s": 0.25, "simulation.control_dt_s": 0.5}),
    ],
    "midcourse": [
        ("phoenix-midcourse", 20, {}),
        ("phoenix-midcourse-none", 100, {}),
        ("phoenix-midcourse-nav03", 4, {}),
    ],
    "intercept": [
        ("bennu-apn", 400, {}),
        ("bennu-pn3", 400, {"guidance.dt_s": 0.5, "navigation.image_interval_s": 0.5}),
    ],
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--system", choices=sorted(CASES), action="append")
    parser.add_argument("--scale", type=float, default=1.0, help="multiply every run count")
    args = parser.parse_args()
    print(
        f"{'scenario':<24} {'overrides':<44} {'runs':>5} {'estimate s':>10} "
        f"{'measured s':>10} {'est/meas':>8}"
    )
    for system in args.system or sorted(CASES):
        for name, runs, sets in CASES[system]:
            runs = max(2, int(runs * args.scale))
            try:
                scenario = gj.load_scenario(name, sets)
            except gj.ScenarioError as e:
                print(f"{name:<24} {str(sets):<44} refused: {e}")
                continue
            estimate = estimate_cost(scenario, runs)
            study = gj.run_study(scenario, runs=runs, progress=False)
            study = gj.run_study(scenario, runs=runs, progress=False)  # compiled: wall only
            ratio = estimate.seconds / study.wall_s if estimate.seconds else float("nan")
            print(
                f"{name:<24} {str(sets):<44} {runs:>5} {estimate.seconds or 0:>10.3g} "
                f"{study.wall_s:>10.3g} {ratio:>8.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
