"""How good is the cost estimate that ``run_study`` checks before it builds or compiles anything?

For the packaged scenarios and off-nominal variations of each system, runs a study and prints
the estimate (:func:`gnc_jax.estimate_cost`: the system's ``steps_per_run`` x its measured
``step_seconds``) next to the measured wall time after compilation, and their ratio. The
systems' ``step_seconds`` constants come from this script; the estimate is meant to be within
a factor of about 3, enough to refuse a runaway study and to size progress chunks.

    python benchmarks/cost_calibration.py [--system impactor] [--scale 1.0]
    python benchmarks/cost_calibration.py --device gpu [--system intercept] [--scale 1.0]
    python benchmarks/cost_calibration.py --fit --system impactor

``--device gpu`` (or ``--fit`` on the CPU) fits a system's cost model on that platform
(``StepCost``: seconds per run-step and per sequential step) from two studies of its example
in one chunk each, a small and a large one (wall = steps x latency + runs x steps x
throughput; on the CPU the large one a chunk of the cache-sized plan), prints the
``StepCost`` to put in the system's ``step_costs`` and the estimate against the measured wall
for the cases above.
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


FIT_CASES = {  # platform -> (scenario, small and large run count), each run in one chunk
    "gpu": {
        "impactor": ("deep-impact-los", 2_000, 100_000),
        "capsule": ("lunar-skip-entry", 10_000, 100_000),
        "intercept": ("bennu-apn", 2_000, 20_000),
        "midcourse": ("phoenix-midcourse", 200, 2_000),
    },
    "cpu": {  # the large one: a chunk of the 2-core machine's plan
        "impactor": ("deep-impact-los", 64, 4_096),
        "intercept": ("bennu-apn", 16, 1_000),
        "capsule": ("lunar-skip-entry", 16, 512),
    },
}


def fit_device(system: str, device: str, scale: float):
    """The system's :class:`~gnc_jax.systems.StepCost` on ``device``, from two studies."""
    from gnc_jax.backend import describe, select
    from gnc_jax.systems import StepCost

    name, small, large = FIT_CASES[select(device).platform][system]
    scenario = gj.load_scenario(name)
    steps = gj.get_system(scenario.kind).steps_per_run(scenario.config)
    walls = []
    for runs in (max(2, int(small * scale)), max(4, int(large * scale))):
        for _ in range(2):  # the second call reuses the executable: its wall is the figure
            study = gj.run_study(
                scenario, runs=runs, chunk_size=runs, progress=False, device=device
            )
        walls.append((runs, study.wall_s))
    (n1, w1), (n2, w2) = walls
    d = select(device).count  # the model's throughput term is per device: ceil(runs / d)
    p1, p2 = -(-n1 // d), -(-n2 // d)
    throughput = max((w2 - w1) / ((p2 - p1) * steps), 0.0)
    latency = max((w1 - p1 * steps * throughput) / steps, 0.0)
    kind = describe(select(device))["device_kind"]
    return StepCost(throughput, latency, f"{name} on {kind}: {n1} runs {w1:.3g} s, {n2} {w2:.3g} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--system", choices=sorted(CASES), action="append")
    parser.add_argument("--scale", type=float, default=1.0, help="multiply every run count")
    parser.add_argument("--device", choices=("cpu", "gpu", "auto"), default="cpu")
    parser.add_argument("--fit", action="store_true", help="fit the StepCost on the CPU too")
    args = parser.parse_args()
    if args.device != "cpu" or args.fit:
        from gnc_jax.backend import select

        cases = FIT_CASES[select(args.device).platform]
        for system in [s for s in args.system or sorted(cases) if s in cases]:
            print(f"{system}: {fit_device(system, args.device, args.scale)!r}", flush=True)
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
            estimate = estimate_cost(scenario, runs, device=args.device)
            for _ in range(2):  # the second call is compiled: wall only
                study = gj.run_study(scenario, runs=runs, progress=False, device=args.device)
            ratio = estimate.seconds / study.wall_s if estimate.seconds else float("nan")
            print(
                f"{name:<24} {str(sets):<44} {runs:>5} {estimate.seconds or 0:>10.3g} "
                f"{study.wall_s:>10.3g} {ratio:>8.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
