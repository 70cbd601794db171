"""The filter's noise model (``navigation.model_*``) apart from the truth's error sources:
unset it is the truth's; set, a perfect sensor can be flown with a filter that stays
consistent."""

import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.systems.impactor.errors import UG, URAD
from gnc_jax.systems.impactor.system import ImpactorSystem

# Every error source the filter models, at the packaged value (file units).
PACKAGED = {
    "image_processing_urad": 10.0,
    "attitude_noise_urad": 30.0,
    "attitude_bias_urad": 100.0,
    "accel_bias_ug": 50.0,
    "accel_noise_ug": 10.0,
}
PERFECT = {f"errors.{k}": 0.0 for k in (*PACKAGED, "attitude_control_urad", "burn_magnitude_pct")}
MODEL = {f"navigation.model_{k}": v for k, v in PACKAGED.items()}


def _study(overrides):
    sc = gj.load_scenario("deep-impact-los", {**ImpactorSystem.test_overrides, **overrides})
    # in chunks of four on every device: the program tests/test_family.py compiles
    return gj.run_study(sc, runs=16, seed=5, chunk_size=4, progress=False)


def test_unset_the_model_is_the_truth_and_set_it_replaces_it():
    sim, _ = gj.build(gj.load_scenario("deep-impact-los", {"errors.accel_noise_ug": 3.0}))
    assert sim.noise_model == sim.errors  # the same arrays: today's filter, bit for bit
    sim, _ = gj.build(
        gj.load_scenario("deep-impact-los", {"navigation.model_image_processing_urad": 0.0})
    )
    assert float(sim.noise_model.image_processing_rad) == 0.0
    assert float(sim.errors.image_processing_rad) == pytest.approx(10.0 * URAD)
    assert float(sim.noise_model.accel_bias_mps2) == pytest.approx(50.0 * UG)


def test_a_perfect_sensor_with_the_packaged_model_keeps_navigation():
    """Every truth error at 0: a filter that believes its angles perfect loses navigation in
    most runs; with the packaged noise model it keeps it in every run. Setting the model to
    the truth's values by hand reproduces the unset outcomes exactly."""
    coupled = _study(PERFECT)
    assert coupled.summary()["failed_by_status"].get("nav_lost", 0) >= 8
    modelled = _study({**PERFECT, **MODEL})
    assert modelled.summary()["failed"] == 0
    assert np.all(modelled.status == gj.Status.ok)
    same = _study({**PERFECT, **{k: 0.0 for k in MODEL}})
    for name, values in coupled.outcomes.items():
        np.testing.assert_array_equal(same.outcomes[name], values, err_msg=name)
