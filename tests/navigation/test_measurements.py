"""Measurement front ends and the generic EKF update, against independent references: a numpy
Joseph update with finite-difference Jacobians, the Gaussian noise model's moments, and the
scenario schema's list of front ends."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.navigation import (
    AbstractMeasurement,
    Exposure,
    GaussianLOSMeasurement,
    Measurement,
    NavEstimate,
    camera_attitude,
    ekf_update,
    los_angles,
    los_model,
    measurement_class,
    predict_measurement,
    register_measurement,
    update_los,
)
from gnc_jax.params import schema_of
from gnc_jax.systems.impactor.build import measurement_setup
from gnc_jax.systems.impactor.params import ImpactorParams, NavigationParams

ALL_MEASUREMENTS = sorted(AbstractMeasurement.measurements)


def _range_and_rate(x):
    """A nonlinear measurement other than the LOS: range and range rate."""
    r, v = x[:3], x[3:]
    rho = jnp.sqrt(r @ r)
    return jnp.stack([rho, r @ v / rho])


def _numpy_update(x, p, z, h, r_cov):
    """Textbook EKF update: central-difference Jacobian, K = P H^T S^-1, P = (I - K H) P."""
    hj = np.zeros((len(z), 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = 1e-5 * max(abs(x[j]), 1.0)
        hj[:, j] = (np.asarray(h(x + e)) - np.asarray(h(x - e))) / (2 * e[j])
    s = hj @ p @ hj.T + r_cov
    k = p @ hj.T @ np.linalg.inv(s)
    return x + k @ (z - np.asarray(h(x))), (np.eye(6) - k @ hj) @ p, s


def test_generic_update_matches_a_numpy_kalman_update():
    rng = np.random.default_rng(4)
    x = np.concatenate([rng.normal(size=3) * 1e6, rng.normal(size=3) * 1e3])
    p = np.diag([1e6, 4e6, 9e6, 1.0, 4.0, 9.0])
    r_cov = np.diag([100.0**2, 0.1**2])
    z = np.asarray(_range_and_rate(x)) + np.array([120.0, -0.05])
    nav = NavEstimate(jnp.asarray(x), jnp.asarray(p))
    predicted = predict_measurement(nav, _range_and_rate, jnp.asarray(r_cov))
    updated, innovation = ekf_update(nav, jnp.asarray(z), predicted)
    x_ref, p_ref, s_ref = _numpy_update(x, p, z, _range_and_rate, r_cov)
    np.testing.assert_allclose(np.asarray(predicted.s), s_ref, rtol=1e-7)
    np.testing.assert_allclose(np.asarray(updated.x), x_ref, rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(np.asarray(updated.p), p_ref, rtol=1e-6, atol=1e-9 * p.max())
    np.testing.assert_allclose(np.asarray(innovation), [120.0, -0.05], rtol=1e-9)
    np.testing.assert_array_equal(np.asarray(updated.p), np.asarray(updated.p).T)


def test_update_los_is_the_generic_update_of_the_los_model():
    rng = np.random.default_rng(5)
    r = np.array([-3e7, 2e5, -1e5])
    nav = NavEstimate(jnp.asarray(np.concatenate([r, [1e4, 5.0, 2.0]])), jnp.eye(6) * 1e6)
    c = camera_attitude(jnp.asarray(-r), jnp.array([0.0, 0.0, 1.0]))
    z = jnp.asarray(rng.normal(size=2) * 1e-5)
    a, ia = update_los(nav, z, c, 1e-5)
    b, ib = ekf_update(nav, z, predict_measurement(nav, los_model(c), (1e-5) ** 2 * jnp.eye(2)))
    for u, w in ((a.x, b.x), (a.p, b.p), (ia, ib)):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(w))


def test_rejected_measurement_leaves_the_estimate_unchanged():
    nav = NavEstimate(jnp.arange(1.0, 7.0) * 1e5, jnp.eye(6) * 1e4)
    predicted = predict_measurement(nav, _range_and_rate, jnp.eye(2))
    z = _range_and_rate(nav.x) + 50.0
    kept, _ = ekf_update(nav, z, predicted, jnp.asarray(False))
    moved, _ = ekf_update(nav, z, predicted, jnp.asarray(True))
    np.testing.assert_array_equal(np.asarray(kept.x), np.asarray(nav.x))
    np.testing.assert_array_equal(np.asarray(kept.p), np.asarray(nav.p))
    assert not np.allclose(np.asarray(moved.x), np.asarray(nav.x))


def test_registry_holds_the_schema_front_ends():
    """The declared choices of ``navigation.measurement`` are the packaged front ends, and the
    impactor's schema offers every registered one."""
    declared = schema_of(NavigationParams, "navigation")["measurement"].choices
    offered = gj.get_system("impactor").schema()["navigation"]["measurement"].choices
    assert set(ALL_MEASUREMENTS) == set(declared) == set(offered)
    for name in ALL_MEASUREMENTS:
        assert measurement_class(name).measurement_name == name
    with pytest.raises(ValueError, match="unknown measurement"):
        measurement_class("pixels")
    with pytest.raises(ValueError, match="already registered"):
        register_measurement("noise")(type("Other", (GaussianLOSMeasurement,), {}))


def _scene(range_m=2e7):
    r_true = jnp.array([-range_m, 3e3, -2e3])  # impactor minus target
    c = camera_attitude(-r_true, jnp.array([0.0, 0.0, 1.0]))
    nav = NavEstimate(jnp.concatenate([r_true, jnp.array([1e4, 0.0, 0.0])]), jnp.eye(6))
    predicted = predict_measurement(nav, los_model(c), (10e-6) ** 2 * jnp.eye(2))
    return Exposure(-r_true, c, c), nav, predicted


@pytest.mark.parametrize("name", ALL_MEASUREMENTS)
def test_every_front_end_measures_the_true_los(name, key):
    """Each registered front end, built from the packaged image scenario, returns the true
    angles within a few times the 10 urad image-processing error, under jit."""
    config = gj.load_scenario("autonav-predictive").config
    front_end = measurement_class(name).from_setup(measurement_setup(ImpactorParams.of(config)))
    exposure, nav, predicted = _scene()
    noise = jax.random.normal(key, (2,))
    meas = jax.jit(lambda *args: front_end(*args))(exposure, nav, predicted, noise, key)
    assert isinstance(meas, Measurement)
    assert meas.z.shape == (2,) and bool(meas.valid)
    # Equal to rounding (jit may contract the written-out products into FMAs).
    np.testing.assert_allclose(
        np.asarray(meas.z_true),
        np.asarray(los_angles(exposure.c_true, exposure.los_m)),
        rtol=1e-12,
        atol=1e-18,
    )
    assert np.max(np.abs(np.asarray(meas.z - meas.z_true))) < 50e-6


@pytest.mark.parametrize("planar", [False, True])
def test_gaussian_front_end_noise_moments(planar, key):
    sigma = 7e-6
    front_end = GaussianLOSMeasurement(jnp.asarray(sigma), planar=planar)
    exposure, nav, predicted = _scene()
    n = 20_000
    noise = jax.random.normal(key, (n, 2))
    meas = jax.vmap(lambda w: front_end(exposure, nav, predicted, w, key))(noise)
    err = np.asarray(meas.z - meas.z_true)
    # sample mean within 4 standard errors, sample std within 4 of its standard errors
    assert abs(err[:, 0].mean()) < 4 * sigma / np.sqrt(n)
    assert abs(err[:, 0].std() / sigma - 1.0) < 4 / np.sqrt(2 * n)
    if planar:
        assert np.all(err[:, 1] == 0.0)  # out of plane exactly zero
    else:
        assert abs(err[:, 1].std() / sigma - 1.0) < 4 / np.sqrt(2 * n)
