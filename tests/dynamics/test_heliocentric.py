"""Heliocentric cruise dynamics against independent references: plan94 itself (ephemeris
table), Kepler's equation (energy conservation), scipy's DOP853 on the same vector field
(propagation and closest approach), finite differences (gravity gradient, STM)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gnc_jax import time as gtime
from gnc_jax.dynamics import heliocentric as hc
from gnc_jax.dynamics.ephemeris import AU_M, GM_SUN, planet_state, planet_states
from gnc_jax.geometry.kepler import propagate_kepler

T_FIX = gtime.parse_epoch("2007-09-01")
T_ENC = gtime.parse_epoch("2008-04-26")
DAY = 86400.0


@pytest.fixture(scope="module")
def table():
    return hc.EphemerisTable.spanning(T_FIX, T_ENC + 30 * DAY)


@pytest.fixture(scope="module")
def model(table):
    return hc.HeliocentricModel(srp_m2_per_kg=1.3 * 7.0 / 664.0, ephemeris=table)


@pytest.fixture(scope="module")
def approach(model):
    """A heliocentric state 3 days before a ~6000 km Mars flyby (built by a backward solve)."""
    r_m, v_m = model.planets(T_ENC)
    r_m, v_m = r_m[3], v_m[3]
    # Periapsis state 3600 km from Mars, 5.6 km/s, in a plane containing Mars's velocity.
    u = v_m / jnp.linalg.norm(v_m)
    w = jnp.cross(u, jnp.array([0.0, 0.0, 1.0]))
    w = w / jnp.linalg.norm(w)
    y_p = jnp.concatenate([r_m + 3.6e6 * w, v_m + 5.6e3 * jnp.cross(w, jnp.cross(u, w))])
    y0, status = jax.jit(hc.propagate)(model, T_ENC, y_p, T_ENC - 3 * DAY)
    assert status == 0
    return y0


def test_ephemeris_table_reproduces_plan94(table):
    ts = T_FIX + np.random.default_rng(0).uniform(0.0, 260.0 * DAY, 400)
    pos, vel = jax.jit(jax.vmap(table.positions_rates))(jnp.asarray(ts))

    def exact(t):
        return jax.jvp(lambda tt: planet_states(tt)[0], (t,), (jnp.ones_like(t),))

    pos_ref, vel_ref = jax.jit(jax.vmap(exact))(jnp.asarray(ts))
    pos_err = np.abs(pos - pos_ref).max(axis=(0, 2))
    vel_err = np.abs(vel - vel_ref).max(axis=(0, 2))
    assert pos_err[0] < 20.0  # Mercury (e = 0.21): the largest high derivatives
    assert np.all(pos_err[1:] < 0.05)  # Venus..Neptune, m
    assert np.all(vel_err[1:] < 1e-6)  # m/s
    # plan94's own velocity is the osculating two-body one, not the derivative (up to m/s)
    _, v_plan94 = planet_state(3, T_FIX + 100 * DAY)
    assert np.abs(np.asarray(v_plan94) - np.asarray(exact(T_FIX + 100 * DAY)[1][3])).max() > 0.1


def test_two_body_propagation_conserves_energy_and_matches_kepler():
    """Planets and SRP off: the 238-day cruise is a Kepler ellipse around the Sun."""
    model = hc.HeliocentricModel(gm_planets=jnp.zeros(8))
    r0 = jnp.array([1.2 * AU_M, 0.3 * AU_M, 0.05 * AU_M])
    v0 = jnp.array([-5e3, 28e3, 1e3])
    t1 = T_FIX + 238 * DAY
    y1, status = jax.jit(hc.propagate)(model, T_FIX, jnp.concatenate([r0, v0]), t1)
    assert status == 0
    r1, v1 = propagate_kepler(r0, v0, t1 - T_FIX, GM_SUN)
    np.testing.assert_allclose(y1[:3], r1, rtol=0, atol=5.0)  # m over 238 days
    np.testing.assert_allclose(y1[3:], v1, rtol=0, atol=1e-6)

    def energy(y):
        return 0.5 * y[3:] @ y[3:] - GM_SUN / jnp.linalg.norm(y[:3])

    e0 = energy(jnp.concatenate([r0, v0]))
    assert abs(float(energy(y1) - e0)) < 1e-11 * abs(float(e0))


def test_propagation_matches_scipy_dop853_on_the_same_vector_field(model, approach):
    """238-day cruise with all perturbations, and the flyby arc through periapsis."""
    field = jax.jit(lambda t, y: hc.vector_field(t, y, model))

    def ivp(t0, y0, t1, **kw):
        sol = solve_ivp(
            lambda t, y: np.asarray(field(t, y)),
            (t0, t1),
            np.asarray(y0),
            method="DOP853",
            rtol=1e-13,
            atol=1e-7,
            **kw,
        )
        assert sol.success
        return sol

    y0 = jnp.concatenate([jnp.array([1.4e11, 5e10, 2e10]), jnp.array([-1.2e4, 2.4e4, 1.0e4])])
    y1, _ = jax.jit(hc.propagate)(model, T_FIX, y0, T_FIX + 238 * DAY)
    ref = ivp(T_FIX, y0, T_FIX + 238 * DAY)
    np.testing.assert_allclose(y1[:3], ref.y[:3, -1], rtol=0, atol=20.0)  # m
    np.testing.assert_allclose(y1[3:], ref.y[3:, -1], rtol=0, atol=1e-5)  # m/s

    # The closest approach: diffrax event + Kepler refinement vs scipy's event root.
    enc = jax.jit(hc.propagate_to_encounter)(model, T_ENC - 3 * DAY, approach, T_ENC + 3 * DAY)
    assert enc.status == 0

    def closest(t, y):
        r, v = hc.relative_state(model, t, jnp.asarray(y))
        return float(r @ v)

    closest.terminal, closest.direction = True, 1.0
    ref = ivp(T_ENC - 3 * DAY, approach, T_ENC + 3 * DAY, events=closest)
    t_ref, y_ref = ref.t_events[0][0], ref.y_events[0][0]
    assert float(enc.t_s) == pytest.approx(t_ref, abs=1e-3)  # s
    np.testing.assert_allclose(enc.state[:3], y_ref[:3], rtol=0, atol=0.05)
    assert abs(float(enc.r_rel @ enc.v_rel)) < 1e-6 * float(
        jnp.linalg.norm(enc.r_rel) * jnp.linalg.norm(enc.v_rel)
    )
    assert float(enc.t_s) == pytest.approx(T_ENC, abs=60.0)
    # a window that ends before the closest approach is a time-out, not a wrong encounter
    short = jax.jit(hc.propagate_to_encounter)(model, T_ENC - 3 * DAY, approach, T_ENC - DAY)
    assert short.status == gj_status("time_out")


def gj_status(name):
    from gnc_jax import Status

    return int(getattr(Status, name))


def test_gravity_gradient_and_srp_against_independent_forms(model):
    r = jnp.array([2.0e11, -4.0e10, 3.0e10])
    g = hc.gravity_gradient(model, T_FIX, r)
    g_ad = jax.jacfwd(lambda x: hc.acceleration(model, T_FIX, x))(r)
    np.testing.assert_allclose(g, g_ad, rtol=1e-10, atol=1e-30)
    # Cannonball SRP: P C_r A / m at 1 AU, pointing away from the Sun.
    bare = hc.HeliocentricModel(gm_sun=0.0, gm_planets=jnp.zeros(8), srp_m2_per_kg=0.01)
    a = hc.acceleration(bare, T_FIX, jnp.array([AU_M, 0.0, 0.0]))
    np.testing.assert_allclose(a, [4.5605e-6 * 0.01, 0.0, 0.0], rtol=1e-12)


def test_state_transition_matrix_matches_finite_differences(model):
    y0 = jnp.concatenate([jnp.array([1.4e11, 5e10, 2e10]), jnp.array([-1.2e4, 2.4e4, 1.0e4])])
    t1 = T_FIX + 100 * DAY
    y1, phi_v, status = jax.jit(hc.propagate_with_stm)(model, T_FIX, y0, t1)
    assert status == 0
    prop = jax.jit(lambda y: hc.propagate(model, T_FIX, y, t1)[0])
    # Φ is in the error norm, so the steps (and the state, within tolerance) differ slightly.
    np.testing.assert_allclose(y1[:3], prop(y0)[:3], rtol=0, atol=1.0)
    h = 1e-2  # m/s
    fd = np.stack(
        [(prop(y0.at[3 + j].add(h)) - prop(y0.at[3 + j].add(-h))) / (2 * h) for j in range(3)],
        axis=1,
    )
    np.testing.assert_allclose(phi_v, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())
