"""Camera model and EKF against scipy rotations and an independent numpy Kalman update."""

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gnc_jax.geometry import b_plane_frame, b_plane_position_covariance
from gnc_jax.navigation import (
    NavEstimate,
    camera_attitude,
    los_angles,
    project,
    propagate_covariance,
    small_rotation,
    update_los,
)
from gnc_jax.navigation.camera import SERIES_ANGLE_MAX, rotate_rows, small_rotation_entries
from gnc_jax.systems.impactor.navigation import attitude_bias_covariance


def test_small_rotation_matches_scipy():
    rng = np.random.default_rng(0)
    for scale in (1e-6, 1e-3, 1.0):
        theta = rng.normal(size=3) * scale
        np.testing.assert_allclose(
            np.asarray(small_rotation(jnp.asarray(theta))),
            Rotation.from_rotvec(theta).as_matrix(),
            atol=1e-15,
        )
    np.testing.assert_allclose(np.asarray(small_rotation(jnp.zeros(3))), np.eye(3))


def test_series_rotation_matches_scipy_up_to_pi():
    # small_rotation_entries (power series, no trigonometry) against scipy's rotation vectors,
    # from 1e-9 rad to its stated limit of pi; beyond it the truncated series drifts (shown).
    rng = np.random.default_rng(3)
    for angle in (1e-9, 1e-4, 0.01, 0.3, 1.0, 2.0, 3.0, SERIES_ANGLE_MAX):
        for _ in range(20):
            axis = rng.normal(size=3)
            theta = angle * axis / np.linalg.norm(axis)
            got = np.array(small_rotation_entries(jnp.asarray(theta)), dtype=float)
            np.testing.assert_allclose(got, Rotation.from_rotvec(theta).as_matrix(), atol=3e-15)
    theta = np.array([0.0, 0.0, 12.0])
    far = np.array(small_rotation_entries(jnp.asarray(theta)), dtype=float)
    assert np.abs(far - Rotation.from_rotvec(theta).as_matrix()).max() > 1e-4
    rows = tuple(jnp.asarray(r) for r in rng.normal(size=(3, 3)))
    entries = small_rotation_entries(jnp.asarray([1e-3, -2e-3, 5e-4]))
    np.testing.assert_allclose(
        np.stack(rotate_rows(entries, rows)),
        np.array(entries, dtype=float) @ np.stack(rows),
        rtol=1e-14,
        atol=1e-15,
    )


def test_pinhole_projection():
    los = jnp.array([1.0, 0.01, -0.02])
    c = camera_attitude(jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 0.0, 1.0]))
    cm = np.asarray(c)
    np.testing.assert_allclose(cm @ cm.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(cm[2], [1, 0, 0])
    xc = cm @ np.asarray(los)
    np.testing.assert_allclose(np.asarray(project(c, los, 2.103)), 2.103 * xc[:2] / xc[2])
    np.testing.assert_allclose(
        np.asarray(los_angles(c, jnp.array([2.0, 0, 0]))), [0, 0], atol=1e-16
    )


def test_ekf_update_matches_numpy_kalman_update():
    rng = np.random.default_rng(1)
    r = np.array([3e7, 2e4, -1e4])
    x = np.concatenate([r, [-1.02e4, 0.1, 0.2]])
    a = rng.normal(size=(6, 6)) * np.array([1e4, 1e3, 1e3, 0.1, 0.1, 0.1])[:, None]
    p = a @ a.T + np.diag([1e6, 1e6, 1e6, 1e-4, 1e-4, 1e-4])
    c = np.asarray(camera_attitude(jnp.asarray(-r), jnp.array([0.0, 0.0, 1.0])))
    z = np.array([3e-5, -1e-5])
    sigma = 3e-5

    def h(xx):
        xc = c @ (-xx[:3])
        return xc[:2] / xc[2]

    hj = np.zeros((2, 6))
    for j in range(3):
        e = np.zeros(6)
        e[j] = 1.0
        hj[:, j] = (h(x + e) - h(x - e)) / 2.0
    s = hj @ p @ hj.T + sigma**2 * np.eye(2)
    k = p @ hj.T @ np.linalg.inv(s)
    x_ref = x + k @ (z - h(x))
    p_ref = (np.eye(6) - k @ hj) @ p

    nav, innov = update_los(
        NavEstimate(jnp.asarray(x), jnp.asarray(p)), jnp.asarray(z), jnp.asarray(c), sigma
    )
    np.testing.assert_allclose(np.asarray(nav.x), x_ref, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(np.asarray(nav.p), p_ref, rtol=1e-6, atol=1e-9 * np.abs(p).max())
    np.testing.assert_allclose(np.asarray(innov), z - h(x), rtol=1e-9)


def test_covariance_propagation_matches_sampling():
    rng = np.random.default_rng(2)
    p0 = np.diag([1e6, 4e6, 9e6, 0.01, 0.04, 0.09])
    dt, q = 15.0, 1e-6
    p1 = np.asarray(propagate_covariance(jnp.asarray(p0), dt, q, 0.0))
    n, steps = 20000, 150
    x = rng.multivariate_normal(np.zeros(6), p0, size=n)
    h = dt / steps
    for _ in range(steps):  # white acceleration of density q
        w = rng.normal(size=(n, 3)) * np.sqrt(q / h)
        x[:, :3] += x[:, 3:] * h + 0.5 * w * h * h
        x[:, 3:] += w * h
    scale = np.sqrt(np.outer(np.diag(p1), np.diag(p1)))
    # sampling error of a normalised covariance element is ~1/sqrt(n) = 0.007
    assert np.abs((np.cov(x.T) - p1) / scale).max() < 0.035


def test_attitude_bias_covariance_leaves_the_b_plane_unchanged():
    r = jnp.array([7.344e7, 0.0, 0.0])
    v = jnp.array([-1.02e4, 0.0, 0.0])
    pb = attitude_bias_covariance(r, v, 100e-6)
    # the rotation moves the lateral velocity by |v| * sigma ...
    assert float(jnp.sqrt(pb[4, 4])) == pytest.approx(1.02, rel=1e-12)
    # ... but not the predicted impact point
    c = b_plane_frame(v, jnp.array([0.0, 0.0, 1.0]))
    d = b_plane_position_covariance(pb, 7200.0, c)
    assert float(jnp.abs(d).max()) < 1e-12 * float(pb[1, 1])
