"""Regressions of the fuzz campaign (``tests/fuzzing.py``) in the midcourse and intercept
systems: cases that must be refused in one line before anything is compiled, and the cost
models behind that refusal."""

import math

import pytest

import gnc_jax as gj
from gnc_jax.montecarlo import estimate_cost


def scenario(name, overrides):
    system = gj.get_system(name)
    return gj.load_scenario(system.example, {**system.test_overrides, **overrides})


def test_intercept_steps_are_the_loop_lengths_the_simulation_is_built_with():
    """The cost model counts what ``simulation.pn.build`` sizes: guidance steps, images and
    the final coast (weights: an image 1.4 steps; perfect navigation 0.4 per step)."""
    system = gj.get_system("intercept")
    for overrides in ({}, {"navigation.image_interval_s": 5.0}, {"guidance.coast_s": 900.0}):
        sc = scenario("intercept", overrides)
        sim, _ = gj.build(sc)
        expected = sim.n_images * sim.steps_per_image + 1.4 * sim.n_images + sim.coast_steps
        assert system.steps_per_run(sc.config) == pytest.approx(expected)
    sc = scenario("intercept", {"navigation.model": "perfect"})
    sim, _ = gj.build(sc)
    expected = 0.4 * sim.n_images * sim.steps_per_image + sim.coast_steps
    assert system.steps_per_run(sc.config) == pytest.approx(expected)


@pytest.mark.parametrize(
    "name, overrides",
    [
        # a guidance step of 1e-300 s: 2e303 steps, once an OverflowError or a hang in build
        (
            "intercept",
            {
                "guidance.dt_s": 1e-300,
                "spacecraft.pulse_width_s": 1e-300,
                "navigation.image_interval_s": 1e-300,
            },
        ),
        # a 100x longer approach at a 1 ms step, images every step
        (
            "intercept",
            {
                "approach.impactor_position_km": [1.3417501e8, 2.04e6, 0.0],
                "guidance.dt_s": 1e-3,
                "spacecraft.pulse_width_s": 1e-3,
                "navigation.image_interval_s": 1e-3,
            },
        ),
        # 1000 fixes of 50 Newton iterations with central differences, a million steps per arc
        (
            "midcourse",
            {
                "navigation.fixes": 1000,
                "navigation.interval_days": 0.2,
                "guidance.autonomous.iterations": 50,
                "guidance.autonomous.sensitivity": "central_difference",
                "dynamics.max_steps": 1_000_000,
                "dynamics.rtol": 1e-15,
            },
        ),
    ],
)
def test_a_runaway_study_is_refused_by_its_cost_before_compilation(name, overrides, monkeypatch):
    sc = scenario(name, overrides)
    cost = estimate_cost(sc, runs=2)
    assert cost.seconds > 360.0  # minutes, for two runs
    built = []
    monkeypatch.setattr(gj.get_system(name), "build", lambda s: built.append(s))
    with pytest.raises(gj.ScenarioError) as refused:
        gj.run_study(sc, runs=2, progress=False, max_hours=0.1)
    message = str(refused.value)
    assert message.startswith("cost: ") and "\n" not in message
    assert not built  # refused before the simulation is built or compiled


@pytest.mark.parametrize("name", ["intercept", "midcourse"])
def test_cost_estimates_are_finite_and_positive_for_the_examples(name):
    cost = estimate_cost(scenario(name, {}), runs=1000)
    assert cost.steps_per_run > 0 and math.isfinite(cost.seconds)
    # the measured cost models (benchmarks/cost_calibration.py --fit for the intercept,
    # benchmarks/cost_midcourse_intercept.py for the midcourse) put a 1000-run study of the
    # short examples between 0.05 s and a minute on two cores (0.09 s and 14 s)
    assert 0.05 < cost.seconds < 60.0


def test_target_elements_inside_the_sun_are_refused_in_one_line():
    """Fuzz case: ``bennu-3d`` with ``semi_major_axis_au = 1e-300`` once raised
    ``ValueError: cannot convert float NaN to integer`` in ``simulation.pn.build`` (the
    target's direction 0/0, then a NaN time of flight sizing the loops)."""
    for a_au in (1e-300, 1e-3):
        with pytest.raises(gj.ScenarioError) as refused:
            scenario(
                "intercept",
                {
                    "approach.geometry": "bennu-3d",
                    "approach.eccentricity": 0.99,
                    "approach.semi_major_axis_au": a_au,
                },
            )
        message = str(refused.value)
        assert message.startswith("approach.semi_major_axis_au: ") and "\n" not in message
    # the Sun's radius is the bound: r = a (1 - e^2) / (1 + e cos nu) just above it loads
    e, nu = 0.5, 0.0
    a_au = 1.001 * 6.957e8 * (1 + e * math.cos(nu)) / (1 - e * e) / 1.495978707e11
    sc = scenario(
        "intercept",
        {
            "approach.geometry": "bennu-3d",
            "approach.eccentricity": e,
            "approach.true_anomaly_deg": 0.0,
            "approach.semi_major_axis_au": a_au,
        },
    )
    assert sc["approach.semi_major_axis_au"] == a_au
