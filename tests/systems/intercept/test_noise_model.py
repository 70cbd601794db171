"""The intercept filter's LOS noise (``navigation.model_attitude_urad``): unset it is the
truth's ``errors.attitude_urad``, set it replaces it in the filter only."""

import pytest

import gnc_jax as gj


def test_the_filter_noise_is_the_truth_unless_set():
    sim, _ = gj.build(gj.load_scenario("bennu-pn3", {"errors.attitude_urad": 50.0}))
    assert sim.model_attitude_rad is sim.errors.attitude_rad
    sim, _ = gj.build(
        gj.load_scenario(
            "bennu-pn3", {"errors.attitude_urad": 0.0, "navigation.model_attitude_urad": 320.0}
        )
    )
    assert float(sim.model_attitude_rad) == pytest.approx(320e-6)
    assert float(sim.errors.attitude_rad) == 0.0
    assert float(sim.measurement.sigma_rad) == 0.0  # the truth's draws stay perfect
