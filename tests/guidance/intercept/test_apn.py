"""Augmented PN (seed 004 eqs. 4-12) and the Schmitt trigger against independent references:
finite differences of the geometry, the paper's scalar planar formulas written out literally,
straight-line zero-effort miss, and the hard logic as the relaxed trigger's limit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax.dynamics.intercept import MU_SUN, InterceptDynamics
from gnc_jax.guidance.intercept.apn import (
    APNState,
    AugmentedPNGuidance,
    PNGuidanceContext,
    PNNavigation,
    augmented_pn_command,
    closing_speed,
    los_angle,
    los_angle_rate,
    navigation_coefficient,
    pulse_train_estimate,
)
from gnc_jax.guidance.trigger import schmitt_trigger

DYN = InterceptDynamics(jnp.asarray(MU_SUN), jnp.asarray(0.0), jnp.asarray(245.0))


def _planar_geometry(seed):
    rng = np.random.default_rng(seed)
    r = np.array([rng.normal() * 1e6, rng.uniform(1e7, 9e8), 0.0])  # impactor minus target
    v = np.array([rng.normal() * 3.0, -rng.uniform(5e3, 1.5e4), 0.0])
    return r, v


@pytest.mark.parametrize("seed", range(4))
def test_los_rate_and_closing_speed_are_derivatives_of_the_geometry(seed):
    r, v = _planar_geometry(seed)
    rho, rho_dot = -r, -v
    # 5-point central differences with a step of 1e-3 of the time to go (truncation ~1e-12);
    # the angle is measured from the t = 0 LOS so that rounding stays relative to its change.
    h = 1e-3 * np.linalg.norm(rho) / np.linalg.norm(rho_dot)

    def lam(t):
        p = rho + rho_dot * t
        return np.arctan2(rho[0] * p[1] - rho[1] * p[0], rho @ p)

    rng = lambda t: np.linalg.norm(rho + rho_dot * t)
    d5 = lambda f: (8 * (f(h) - f(-h)) - (f(2 * h) - f(-2 * h))) / (12 * h)
    fd_rate, fd_close = d5(lam), -d5(rng)
    # eq. 4 itself: the LOS angle of the geometry
    assert float(los_angle(jnp.asarray(rho))) == pytest.approx(np.arctan2(rho[1], rho[0]))
    assert float(los_angle_rate(jnp.asarray(rho), jnp.asarray(rho_dot))) == pytest.approx(
        fd_rate, rel=1e-7
    )
    assert float(closing_speed(jnp.asarray(rho), jnp.asarray(rho_dot))) == pytest.approx(
        fd_close, rel=1e-9
    )


def _paper_scalar_command(r_target, r, v, n):
    """Eqs. 4, 5, 8, 10, 11 as printed, with the paper's R = R_T - R_S (= -r)."""
    rx, ry = -r[0], -r[1]
    vx, vy = -v[0], -v[1]
    lam = np.arctan2(ry, rx)
    lam_dot = (rx * vy - ry * vx) / (rx**2 + ry**2)
    vc = -(rx * vx + ry * vy) / np.hypot(rx, ry)
    rs = r_target + r
    nt = (r_target[0] ** 2 + r_target[1] ** 2) ** 1.5
    ns = (rs[0] ** 2 + rs[1] ** 2) ** 1.5
    a_r = (
        MU_SUN * r_target[0] / nt * np.sin(lam)
        + (-MU_SUN * r_target[1]) / nt * np.cos(lam)
        - MU_SUN * rs[0] / ns * np.sin(lam)
        - (-MU_SUN * rs[1]) / ns * np.cos(lam)
    )
    return n * (vc * lam_dot + a_r / 2.0), lam


@pytest.mark.parametrize("seed", range(4))
def test_vector_command_equals_the_papers_scalar_form(seed):
    r, v = _planar_geometry(seed)
    r_target = np.array([1.34175e11, 2e9 * seed, 0.0])
    n = 3.7
    a_vec, u = augmented_pn_command(
        PNNavigation(jnp.asarray(r), jnp.asarray(v), jnp.asarray(r_target)), n, DYN
    )
    a_vec, u = np.asarray(a_vec), np.asarray(u)
    a_scalar, lam = _paper_scalar_command(r_target, r, v, n)
    normal = np.array([-np.sin(lam), np.cos(lam), 0.0])  # the LOS turned by +90 deg
    np.testing.assert_allclose(a_vec, a_scalar * normal, rtol=1e-7, atol=1e-12 * abs(a_scalar))
    assert abs(a_vec @ u) < 1e-12 * np.linalg.norm(a_vec)  # perpendicular to the LOS


@pytest.mark.parametrize("seed", range(4))
def test_command_reduces_the_zero_effort_miss(seed):
    rng = np.random.default_rng(10 + seed)
    r = np.array([rng.normal() * 1e5, 5e8, rng.normal() * 1e5])
    v = np.array([rng.normal(), -1.02e4, rng.normal()])
    nav = PNNavigation(jnp.asarray(r), jnp.asarray(v), jnp.array([1.34175e11, 0.0, 0.0]))
    a, _ = augmented_pn_command(nav, 3.0, InterceptDynamics(mu_sun=jnp.asarray(0.0)))

    def zem(vv):
        t_go = -(r @ vv) / (vv @ vv)
        return np.linalg.norm(r + vv * t_go)

    n = np.asarray(a) / np.linalg.norm(np.asarray(a))
    assert zem(v + 0.01 * n) < zem(v) < zem(v - 0.01 * n)
    # and N V_c lambda_dot = N ZEM / t_go^2 for straight-line motion (PN's textbook identity)
    t_go = -(r @ v) / (v @ v)
    assert float(jnp.linalg.norm(a)) == pytest.approx(3.0 * zem(v) / t_go**2, rel=1e-3)


def test_navigation_coefficient_schedule():
    r0 = 9.36e8
    ranges = np.array([r0, 0.8 * r0, 0.5 * r0, 0.25 * r0, 1e-3 * r0])
    got = np.asarray(navigation_coefficient(jnp.asarray(ranges), r0, 8.0, 2.0))
    np.testing.assert_allclose(got, np.maximum(2.0, 8.0 * (ranges / r0) ** 2))
    assert got[0] == 8.0 and got[-1] == 2.0  # N0 at the start, the floor of 2 at the end
    assert np.all(np.diff(got) <= 0.0)  # decreasing as the range closes
    const = np.asarray(navigation_coefficient(jnp.asarray(ranges), r0, 3.0, 0.0))
    np.testing.assert_array_equal(const, 3.0)  # k = 0: constant N
    # the floor switches in at R/R0 = (2/N0)^(1/k) = 0.5
    assert float(navigation_coefficient(0.5 * r0 * (1 + 1e-9), r0, 8.0, 2.0)) > 2.0
    assert float(navigation_coefficient(0.5 * r0 * (1 - 1e-9), r0, 8.0, 2.0)) == 2.0


@pytest.mark.parametrize(
    "magnitude,prev,expected",
    [
        (5.0, 0.0, 1.0),  # above the on-threshold: fire
        (4.0, 0.0, 1.0),  # exactly at it
        (3.0, 0.0, 0.0),  # inside the band, was off: stay off
        (3.0, 1.0, 1.0),  # inside the band, was on: stay on
        (2.0, 1.0, 0.0),  # at the off-threshold: stop
        (1.0, 1.0, 0.0),
        (1.0, 0.0, 0.0),
    ],
)
def test_schmitt_trigger_hysteresis(magnitude, prev, expected):
    assert float(schmitt_trigger(magnitude, prev, 4.0, 2.0)) == expected


@pytest.mark.parametrize("magnitude,prev", [(5.0, 0.0), (3.0, 0.0), (3.0, 1.0), (1.0, 1.0)])
def test_relaxed_trigger_tends_to_the_hard_logic(magnitude, prev):
    hard = float(schmitt_trigger(magnitude, prev, 4.0, 2.0))
    errs = [
        abs(float(schmitt_trigger(magnitude, prev, 4.0, 2.0, temperature)) - hard)
        for temperature in (0.3, 0.1, 0.03, 0.01)
    ]
    assert errs[-1] < 1e-8
    assert all(b <= a + 1e-15 for a, b in zip(errs, errs[1:]))


def _context(**kw):
    base = dict(
        range0_m=jnp.asarray(9.36e8),
        cutoff_time_s=jnp.asarray(91200.0),
        pulse_fraction=jnp.asarray(0.05),
        dynamics=DYN,
        reference_normal=jnp.array([0.0, 0.0, 1.0]),
        dt_s=1.0,
    )
    base.update(kw)
    return PNGuidanceContext(**base)


def test_law_step_fires_along_the_command_and_coasts_after_cutoff():
    r, v = _planar_geometry(0)
    nav = PNNavigation(jnp.asarray(r), jnp.asarray(v), jnp.array([1.34175e11, 0.0, 0.0]))
    law = AugmentedPNGuidance(a_on_mps2=jnp.asarray(1e-9), a_off_mps2=jnp.asarray(5e-10))
    ctx = _context()
    cmd, st = law.step(law.init(nav, ctx), nav, 0.0, ctx)
    assert float(cmd.throttle) == pytest.approx(0.05)  # the pulse fraction of the step
    np.testing.assert_allclose(
        np.asarray(cmd.direction),
        np.asarray(st.command_mps2) / float(jnp.linalg.norm(st.command_mps2)),
    )
    cmd, _ = law.step(st, nav, 91200.0, ctx)
    assert float(cmd.throttle) == 0.0


def test_law_gradient_wrt_gains_matches_finite_differences():
    r, v = _planar_geometry(1)
    nav = PNNavigation(jnp.asarray(r), jnp.asarray(v), jnp.array([1.34175e11, 0.0, 0.0]))
    ctx = _context()
    st = APNState(jnp.asarray(0.3), jnp.zeros(3), jnp.asarray(8.0))
    a0 = float(jnp.linalg.norm(augmented_pn_command(nav, 8.0 * 0.6**2, DYN)[0]))

    def throttle(gains):
        law = AugmentedPNGuidance(
            n0=gains[0],
            k=gains[1],
            a_on_mps2=gains[2],
            a_off_mps2=gains[3],
            temperature=jnp.asarray(0.1),
            relaxed=True,
        )
        nav_r = nav._replace(r=nav.r * (0.6 * 9.36e8 / jnp.linalg.norm(nav.r)))
        return law.step(st, nav_r, 0.0, ctx)[0].throttle

    gains = jnp.array([8.0, 2.0, 1.1 * a0, 0.6 * a0])
    g = np.asarray(jax.grad(throttle)(gains))
    for i, step in enumerate([1e-4, 1e-5, 1e-4 * a0, 1e-4 * a0]):
        e = np.eye(4)[i] * step
        fd = (throttle(gains + e) - throttle(gains - e)) / (2 * step)
        assert g[i] == pytest.approx(float(fd), rel=1e-5, abs=1e-9 * abs(g).max())
    assert np.all(g != 0.0)


def _brute_force_pulse_trains(z0, big_t, n0, k, n_min, a_on, a_off, coast, accel, dt):
    """The estimate's model stepped by brute force: straight line, trigger on A = N Z / t_go^2."""
    z, dv, on, trains, t = z0, 0.0, False, 0, 0.0
    while big_t - t > coast:
        tgo = big_t - t
        a = max(n_min, n0 * (tgo / big_t) ** k) * z / tgo**2
        was_on = on
        on = a >= a_on or (on and a > a_off)
        trains += on and not was_on
        if on:
            dv += accel * dt
            z -= accel * dt * (tgo - 0.5 * dt)  # exact for constant acceleration over the step
        t += dt
    return dv, trains, z


@pytest.mark.parametrize(
    "n0, k, rho",
    [(8.0, 2.0, 2.0), (3.0, 0.0, 2.0), (8.0, 2.0, 4.0), (3.0, 0.0, 4.0), (8.0, 3.0, 2.0)],
)
def test_pulse_train_estimate_matches_a_brute_force_dead_band_simulation(n0, k, rho):
    # A scaled seed 004 geometry: 1000 s, 2 km miss (impulsive minimum 2 m/s), 10 s coast,
    # an engine that takes ~4 % of the flight for the first train.
    big_t, z0, coast, accel, a_off = 1000.0, 2000.0, 10.0, 0.05, 2e-4
    kw = dict(n0=n0, k=k, n_min=2.0, a_on_mps2=rho * a_off, a_off_mps2=a_off, coast_s=coast)
    est = pulse_train_estimate(z0, big_t, engine_accel_mps2=accel, **kw)
    dv, trains, z = _brute_force_pulse_trains(
        z0,
        big_t,
        accel=accel,
        dt=1e-3,
        **{"n0": n0, "k": k, "n_min": 2.0, "a_on": rho * a_off, "a_off": a_off, "coast": coast},
    )
    assert est.dv_mps == pytest.approx(dv, rel=5e-4)
    assert est.trains == trains
    # the steps overshoot a_off by up to accel dt t_go of miss: the residual only roughly
    assert est.residual_zem_m == pytest.approx(z, rel=0.25)
    # the uncut impulsive form of the docstring
    n_e = n0 if k == 0 else 2.0
    uncut = pulse_train_estimate(
        z0, big_t, coast_s=1e-9 * big_t, **{key: v for key, v in kw.items() if key != "coast_s"}
    )
    closed = z0 / big_t + a_off * big_t * ((1 + np.sqrt(rho)) / np.sqrt(n0 * n_e) - 1 / n0)
    assert uncut.dv_mps == pytest.approx(closed, rel=1e-6)


def test_pulse_train_estimate_rejects_what_it_does_not_model():
    with pytest.raises(ValueError, match="k = 1"):
        pulse_train_estimate(1.0, 1.0, 8.0, 1.0, 2.0, 2.0, 1.0, 0.1)
    with pytest.raises(ValueError, match="a_off <= a_on"):
        pulse_train_estimate(1.0, 1.0, 8.0, 2.0, 2.0, 1.0, 2.0, 0.1)
