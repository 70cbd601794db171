"""The target's B-plane silhouette against brute-force ray casting."""

import jax.numpy as jnp
import numpy as np

from gnc_jax.geometry.bplane import b_plane_frame
from gnc_jax.geometry.silhouette import focusing_factor, silhouette_matrix, silhouette_ratio
from gnc_jax.navigation.camera import small_rotation


def _ray_hits(y, semi_axes, c_body, c_bi):
    """Does the line x = y_T T + y_R R + s S meet the ellipsoid? (quadratic in s)"""
    x0 = y[0] * c_bi[1] + y[1] * c_bi[2]
    a_mat = c_body @ np.diag(1.0 / np.asarray(semi_axes) ** 2) @ c_body.T
    s = c_bi[0]
    qa, qb, qc = s @ a_mat @ s, 2 * x0 @ a_mat @ s, x0 @ a_mat @ x0 - 1.0
    return qb * qb - 4 * qa * qc >= 0.0


def test_silhouette_of_a_rotated_ellipsoid_matches_ray_casting():
    rng = np.random.default_rng(3)
    semi = np.array([3800.0, 2450.0, 1900.0])
    c_body = np.asarray(small_rotation(jnp.array([0.3, -0.5, 0.9])))
    c_bi = np.asarray(b_plane_frame(jnp.array([-10.2e3, 1.5e3, 0.7e3]), jnp.array([0.0, 0, 1])))
    m = silhouette_matrix(jnp.asarray(semi), jnp.asarray(c_body), jnp.asarray(c_bi))
    ys = rng.uniform(-4500.0, 4500.0, size=(3000, 2))
    ratio = np.array([float(silhouette_ratio(jnp.asarray(y), m, 1.0)) for y in ys[:400]])
    hits = np.array([_ray_hits(y, semi, c_body, c_bi) for y in ys[:400]])
    np.testing.assert_array_equal(ratio < 1.0, hits)
    assert 0.2 < hits.mean() < 0.8  # both sides sampled


def test_sphere_silhouette_is_its_disc_and_focusing_is_opik():
    c_bi = np.asarray(b_plane_frame(jnp.array([-10.2e3, 0.0, 0.0]), jnp.array([0.0, 0, 1])))
    m = silhouette_matrix(jnp.full(3, 150.0), jnp.eye(3), jnp.asarray(c_bi))
    np.testing.assert_allclose(np.asarray(m), 150.0**2 * np.eye(2), rtol=1e-14)
    assert abs(float(silhouette_ratio(jnp.array([90.0, 120.0]), m, 1.0)) - 1.0) < 1e-14
    # capture radius of a point mass: b^2 = R^2 (1 + v_esc^2 / v^2), v_esc^2 = 2 mu / R
    mu, r, v = 4.892, 245.0, 0.2
    assert abs(float(focusing_factor(mu, r, v)) ** 2 - (1 + 2 * mu / r / v**2)) < 1e-12
