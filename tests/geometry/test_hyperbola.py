"""Hyperbolic B-plane: an analytic hyperbola built from its B vector, the straight-line limit,
the S ∥ n error and batching."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax.geometry.bplane import BPlaneError, b_plane_crossing, b_plane_frame
from gnc_jax.geometry.hyperbola import b_plane_hyperbolic, check_hyperbolic_b_plane

MU_MARS = 4.2828375816e13  # m³/s²

_b_plane = jax.jit(b_plane_hyperbolic)


def _analytic_hyperbola(s_hat, b_vec, v_inf, mu, true_anomaly):
    """State at ``true_anomaly`` of the hyperbola with incoming asymptote S, B vector B and
    excess speed v∞, in closed form, and the closed-form time to periapsis.

    ĥ = B̂ × Ŝ, e = sqrt(1 + (b v∞²/μ)²), a = -μ/v∞², p = a (1 - e²); the periapsis direction
    ê = Ŝ/e - sqrt(e² - 1)/e (ĥ × Ŝ) follows from Ŝ = ê/e + sqrt(e² - 1)/e (ĥ × ê). The time
    to periapsis is -(e sinh H - H)/n, n = sqrt(μ/(-a)³), tanh(H/2) = sqrt((e-1)/(e+1)) tan(ν/2).
    """
    b = np.linalg.norm(b_vec)
    h_hat = np.cross(b_vec / b, s_hat)
    e = np.sqrt(1.0 + (b * v_inf**2 / mu) ** 2)
    a = -mu / v_inf**2
    p = a * (1.0 - e * e)
    e_hat = s_hat / e - np.sqrt(e * e - 1.0) / e * np.cross(h_hat, s_hat)
    q_hat = np.cross(h_hat, e_hat)
    r = p / (1.0 + e * np.cos(true_anomaly))
    pos = r * (np.cos(true_anomaly) * e_hat + np.sin(true_anomaly) * q_hat)
    vel = np.sqrt(mu / p) * (-np.sin(true_anomaly) * e_hat + (e + np.cos(true_anomaly)) * q_hat)
    hyp = 2.0 * np.arctanh(np.sqrt((e - 1.0) / (e + 1.0)) * np.tan(0.5 * true_anomaly))
    t_to_periapsis = -(e * np.sinh(hyp) - hyp) / np.sqrt(mu / (-a) ** 3)
    return pos, vel, t_to_periapsis


@pytest.mark.parametrize("seed", range(4))
def test_b_plane_of_an_analytic_hyperbola(seed):
    rng = np.random.default_rng(seed)
    s_hat = rng.normal(size=3)
    s_hat /= np.linalg.norm(s_hat)
    normal = np.array([0.0, -0.3978, 0.9175])  # ecliptic pole in EME2000
    c_bi = np.asarray(b_plane_frame(jnp.asarray(s_hat), jnp.asarray(normal)))
    b_t, b_r = rng.uniform(-2e7, 2e7, 2)
    b_vec = b_t * c_bi[1] + b_r * c_bi[2]
    v_inf = rng.uniform(2e3, 8e3)
    e = np.sqrt(1.0 + (np.hypot(b_t, b_r) * v_inf**2 / MU_MARS) ** 2)
    nu_max = np.arccos(-1.0 / e)
    for nu in (-0.97 * nu_max, -0.5 * nu_max, -0.1, 0.0, 0.3 * nu_max, 0.9 * nu_max):
        r, v, t_tof = _analytic_hyperbola(s_hat, b_vec, v_inf, MU_MARS, nu)
        out = _b_plane(r, v, MU_MARS, normal)
        scale = np.hypot(b_t, b_r)
        assert abs(out.b_t - b_t) < 1e-9 * scale
        assert abs(out.b_r - b_r) < 1e-9 * scale
        assert out.v_inf == pytest.approx(v_inf, rel=1e-12)
        np.testing.assert_allclose(out.c_bi, c_bi, atol=1e-9)
        assert out.t_tof == pytest.approx(t_tof, rel=1e-9, abs=1e-6)


def test_straight_line_limit_matches_the_straight_line_crossing():
    """With a negligible μ the asymptote is the trajectory: B and t_TOF of `b_plane_crossing`."""
    rng = np.random.default_rng(7)
    normal = jnp.array([0.0, 0.0, 1.0])
    for _ in range(5):
        r = rng.normal(size=3) * 1e9
        v = -r / np.linalg.norm(r) * 5e3 + rng.normal(size=3) * 300.0
        out = _b_plane(r, v, 1e-6, normal)
        b_line, t_line = b_plane_crossing(jnp.asarray(r), jnp.asarray(v), out.c_bi)
        np.testing.assert_allclose([out.b_t, out.b_r], b_line, rtol=1e-8, atol=1e-3)
        # time of closest approach of the line = its crossing of the plane normal to v
        assert out.t_tof == pytest.approx(float(t_line), rel=1e-8)


def test_asymptote_parallel_to_the_reference_normal_is_a_clear_error():
    s_hat = np.array([0.0, 0.0, 1.0])
    b_vec = np.array([7e6, 0.0, 0.0])
    r, v, _ = _analytic_hyperbola(s_hat, b_vec, 4e3, MU_MARS, -1.0)
    with pytest.raises(BPlaneError, match="parallel to the reference-plane normal"):
        check_hyperbolic_b_plane(r, v, MU_MARS, [0.0, 0.0, 2.0])
    out = _b_plane(r, v, MU_MARS, jnp.array([0.0, 0.0, 1.0]))
    assert np.isnan(out.b_t) and np.isnan(out.b_r)  # inside jit: NaN, flagged as a nan run
    check_hyperbolic_b_plane(r, v, MU_MARS, [0.0, 1.0, 0.0])  # any other plane is fine
    with pytest.raises(BPlaneError, match="not a hyperbola"):
        check_hyperbolic_b_plane([7e6, 0.0, 0.0], [0.0, 2e3, 0.0], MU_MARS, [0.0, 0.0, 1.0])


def test_vmapped_b_plane_equals_the_per_state_loop():
    rng = np.random.default_rng(3)
    normal = jnp.array([0.0, -0.3978, 0.9175])
    states = []
    for _ in range(6):
        s_hat = rng.normal(size=3)
        s_hat /= np.linalg.norm(s_hat)
        b_vec = np.cross(s_hat, rng.normal(size=3)) * 1e7
        states.append(_analytic_hyperbola(s_hat, b_vec, 3.6e3, MU_MARS, -1.5)[:2])
    r, v = (jnp.asarray(np.stack(x)) for x in zip(*states))
    batch = jax.vmap(b_plane_hyperbolic, in_axes=(0, 0, None, None))(r, v, MU_MARS, normal)
    for i in range(6):
        one = _b_plane(r[i], v[i], MU_MARS, normal)
        for a, b in zip(batch[:4], one[:4]):
            assert a[i] == pytest.approx(float(b), rel=1e-12, abs=1e-9)
