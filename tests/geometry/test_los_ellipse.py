"""Geometry of seed 000 §1-2 against brute force, sampling and numpy."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from gnc_jax.geometry import (
    BPlaneError,
    b_plane_crossing,
    b_plane_frame,
    b_plane_position_covariance,
    check_b_plane_frame,
    ellipse_probability,
    error_ellipse,
    los_frame,
    los_rate,
    map_covariance,
    mean_position_error,
    range_rate,
    unforced_miss,
)


def random_geometry(rng):
    rho = rng.normal(size=3) * rng.uniform(1e3, 1e8)
    rho_dot = -rho / np.linalg.norm(rho) * rng.uniform(1e2, 2e4) + rng.normal(size=3) * 50.0
    return rho, rho_dot


def test_unforced_miss_equals_brute_force_closest_approach():
    rng = np.random.default_rng(1)
    for _ in range(50):
        rho, rho_dot = random_geometry(rng)
        t_ca = -rho @ rho_dot / (rho_dot @ rho_dot)
        res = minimize_scalar(
            lambda t, rho=rho, rho_dot=rho_dot: np.linalg.norm(rho + rho_dot * t),
            bracket=(0.0, t_ca * 1.3 + 1.0),
            tol=1e-14,
        )
        brute = np.linalg.norm(rho + rho_dot * res.x)
        grid = np.linalg.norm(
            rho[None] + rho_dot[None] * np.linspace(0, 2 * t_ca, 200001)[:, None], axis=1
        ).min()
        eq7 = float(unforced_miss(jnp.asarray(rho), jnp.asarray(rho_dot)))
        assert eq7 == pytest.approx(brute, rel=1e-7, abs=1e-6)
        assert eq7 <= grid + 1e-6


def test_los_rate_and_range_rate_by_finite_difference():
    rng = np.random.default_rng(2)
    rho, rho_dot = random_geometry(rng)
    h = 1e-3
    u = lambda t: (rho + rho_dot * t) / np.linalg.norm(rho + rho_dot * t)
    dudt = (u(h) - u(-h)) / (2 * h)
    omega = np.asarray(los_rate(jnp.asarray(rho), jnp.asarray(rho_dot)))
    # d(u)/dt = omega x u for the LOS unit vector
    np.testing.assert_allclose(np.cross(omega, u(0.0)), dudt, rtol=1e-6, atol=1e-14)
    rdot = (np.linalg.norm(rho + rho_dot * h) - np.linalg.norm(rho - rho_dot * h)) / (2 * h)
    assert float(range_rate(jnp.asarray(rho), jnp.asarray(rho_dot))) == pytest.approx(
        rdot, rel=1e-7
    )


def test_b_plane_frame_is_right_handed_and_follows_definition():
    v = jnp.array([-10.2e3, 300.0, -50.0])
    h = jnp.array([0.1, -0.2, 1.0])
    c = np.asarray(b_plane_frame(v, h))
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(c) == pytest.approx(1.0)
    np.testing.assert_allclose(c[0], np.asarray(v) / np.linalg.norm(v), atol=1e-15)
    assert abs(c[1] @ np.asarray(h)) < 1e-14  # T lies in the reference plane
    frame = np.asarray(los_frame(jnp.array([1.0, 2.0, 3.0]), jnp.asarray(c[2])))
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-14)


def test_b_plane_frame_parallel_normal_raises():
    with pytest.raises(BPlaneError, match="parallel"):
        check_b_plane_frame([0.0, 0.0, -5.0], [0.0, 0.0, 1.0])
    assert np.all(
        np.isnan(np.asarray(b_plane_frame(jnp.array([0.0, 0, 2]), jnp.array([0.0, 0, 1])))[1])
    )


def test_b_plane_crossing_of_a_straight_line():
    c = b_plane_frame(jnp.array([-1.0, 0.0, 0.0]), jnp.array([0.0, 0.0, 1.0]))
    r = jnp.array([1e6, 2e3, -5e3])
    v = jnp.array([-1e4, 1.0, 2.0])
    b, t = b_plane_crossing(r, v, c)
    assert float(t) == pytest.approx(100.0)
    hit = np.asarray(r + v * t)
    assert abs(hit[0]) < 1e-9
    np.testing.assert_allclose(np.asarray(b), [np.asarray(c[1]) @ hit, np.asarray(c[2]) @ hit])


def test_error_ellipse_matches_numpy_eigendecomposition():
    rng = np.random.default_rng(3)
    for _ in range(30):
        a = rng.normal(size=(2, 2)) * rng.uniform(1, 1e3)
        d = a @ a.T + 1e-3 * np.eye(2)
        e, f, phi_f = (float(x) for x in error_ellipse(jnp.asarray(d)))
        vals, vecs = np.linalg.eigh(d)
        assert e == pytest.approx(np.sqrt(vals[1]), rel=1e-9)
        assert f == pytest.approx(np.sqrt(vals[0]), rel=1e-7)
        minor = vecs[:, 0]
        direction = np.array([np.cos(phi_f), np.sin(phi_f)])
        assert abs(abs(direction @ minor) - 1.0) < 1e-9
        assert float(mean_position_error(jnp.asarray(d))) == pytest.approx(np.hypot(e, f))


def test_ellipse_probability_matches_sampling():
    rng = np.random.default_rng(4)
    cov = np.array([[4.0, 1.5], [1.5, 1.0]])
    x = rng.multivariate_normal([0, 0], cov, size=400_000)
    m2 = np.einsum("ni,ij,nj->n", x, np.linalg.inv(cov), x)  # (B/E)^2 + (B/F)^2 in axes
    for k in (0.5, 1.0, 2.0, 3.0, 3.5):
        p = float(ellipse_probability(k))
        assert np.mean(m2 <= k**2) == pytest.approx(p, abs=3e-3)
    # the paper's Table 1 misprints k = 3.0 and 3.5
    assert float(ellipse_probability(3.0)) == pytest.approx(0.9889, abs=1e-4)
    assert float(ellipse_probability(3.5)) == pytest.approx(0.9978, abs=1e-4)


def test_covariance_mapping_matches_monte_carlo_and_full_product():
    rng = np.random.default_rng(5)
    a = rng.normal(size=(6, 6)) * np.array([100, 100, 100, 0.1, 0.1, 0.1])[:, None]
    p0 = a @ a.T
    t_go = 3000.0
    c = b_plane_frame(jnp.array([-1.0, 0.1, 0.0]), jnp.array([0.0, 0.0, 1.0]))
    d = np.asarray(b_plane_position_covariance(jnp.asarray(p0), t_go, c))
    pf = np.asarray(map_covariance(jnp.asarray(p0), t_go))
    tr = np.asarray(c)[1:]
    np.testing.assert_allclose(d, tr @ pf[:3, :3] @ tr.T, rtol=1e-12)
    x = rng.multivariate_normal(np.zeros(6), p0, size=200_000)
    pos_f = x[:, :3] + t_go * x[:, 3:]
    np.testing.assert_allclose(np.cov((pos_f @ tr.T).T), d, rtol=0.03, atol=1e-6 * np.abs(d).max())


def test_b_plane_covariance_reads_a_packed_covariance_as_the_dense_one():
    """A filter's packed covariance (21 entries) gives the dense matrix's D to the last bit,
    under jit and vmap, and D against the full product Phi P Phi^T."""
    from gnc_jax.navigation.packed_ekf import pack

    rng = np.random.default_rng(9)
    a = rng.normal(size=(4, 6, 6)) * np.array([100, 100, 100, 0.1, 0.1, 0.1])[:, None]
    p0 = jnp.asarray(a @ np.swapaxes(a, 1, 2))
    t_go = jnp.asarray(rng.uniform(1e3, 1e4, size=4))
    c = b_plane_frame(jnp.array([-1.0, 0.1, 0.0]), jnp.array([0.0, 0.0, 1.0]))
    dense = jax.jit(jax.vmap(lambda p, t: b_plane_position_covariance(p, t, c)))(p0, t_go)
    packed = jax.jit(jax.vmap(lambda p, t: b_plane_position_covariance(pack(p), t, c)))(p0, t_go)
    np.testing.assert_array_equal(packed, dense)
    tr = np.asarray(c)[1:]
    for k in range(4):
        pf = np.asarray(map_covariance(p0[k], t_go[k]))
        np.testing.assert_allclose(dense[k], tr @ pf[:3, :3] @ tr.T, rtol=1e-11)


def test_geometry_vmaps():
    rho = jnp.ones((5, 3)) * jnp.arange(1.0, 6.0)[:, None] + jnp.array([1e6, 0, 0])
    rho_dot = jnp.tile(jnp.array([-1e4, 1.0, 0.5]), (5, 1))
    out = jax.vmap(unforced_miss)(rho, rho_dot)
    loop = jnp.stack([unforced_miss(a, b) for a, b in zip(rho, rho_dot)])
    np.testing.assert_allclose(out, loop, rtol=1e-14)
