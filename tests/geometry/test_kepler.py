"""Two-body helpers against scipy (brentq, DOP853) and against each other's independent routes."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from gnc_jax.geometry import kepler

MU_SUN = 1.32712440018e20  # m³/s²
MU_EARTH = 3.986004418e14  # m³/s²
AU = 1.495978707e11  # m
DAY = 86400.0


# Jitted batch entry points shared by the tests (eager op-by-op dispatch would dominate runtime).
_propagate = jax.jit(jax.vmap(kepler.propagate_kepler, in_axes=(0, 0, 0, None)))
_to_state = jax.jit(jax.vmap(kepler.elements_to_state, in_axes=(0, None)))
_to_elements = jax.jit(jax.vmap(kepler.state_to_elements, in_axes=(0, 0, None)))
_solve_elliptic = jax.jit(kepler.solve_kepler_elliptic, static_argnames="n_iter")
_solve_hyperbolic = jax.jit(kepler.solve_kepler_hyperbolic, static_argnames="n_iter")
_true_from_mean = jax.jit(kepler.true_anomaly_from_mean)
_mean_from_true = jax.jit(kepler.mean_anomaly_from_true)


def _two_body_dop853(r0, v0, dt, mu):
    """Reference: Cartesian two-body ODE integrated by scipy's DOP853 at rtol 1e-12."""

    def rhs(_, y):
        r = y[:3]
        return np.concatenate([y[3:], -mu * r / np.linalg.norm(r) ** 3])

    y0 = np.concatenate([r0, v0])
    sol = solve_ivp(rhs, (0.0, dt), y0, method="DOP853", rtol=1e-12, atol=1e-9)
    assert sol.success
    return sol.y[:3, -1], sol.y[3:, -1]


# (r0 [m], v0 [m/s], dt [s], mu): elliptic, hyperbolic, near-parabolic, backwards, multi-rev.
_PROPAGATION_CASES = {
    "earth_like": ([AU, 0.0, 0.0], [0.0, 29.78e3, 0.5e3], 200 * DAY, MU_SUN),
    "earth_mars_transfer": ([AU, 0.1 * AU, 0.0], [-3e3, 33e3, 2e3], 238 * DAY, MU_SUN),
    "hyperbolic": ([AU, 0.0, 0.0], [0.0, 1.6 * 29.78e3, 1e3], 300 * DAY, MU_SUN),
    "near_parabolic": ([AU, 0.0, 0.0], [0.0, 42.1e3, 0.0], 100 * DAY, MU_SUN),
    "backwards": ([AU, 0.0, 0.0], [0.0, 29.78e3, 0.0], -150 * DAY, MU_SUN),
    "leo_15_revs": ([6778e3, 0.0, 0.0], [0.0, 5.0e3, 5.9e3], 15 * 5560.0, MU_EARTH),
    "earth_escape": ([7000e3, 0.0, 0.0], [0.0, 11.5e3, 1.0e3], 5 * DAY, MU_EARTH),
}


@pytest.mark.parametrize("name", sorted(_PROPAGATION_CASES))
def test_propagate_kepler_matches_dop853(name):
    r0, v0, dt, mu = (np.asarray(x, dtype=float) for x in _PROPAGATION_CASES[name])
    r, v = jax.jit(kepler.propagate_kepler)(r0, v0, dt, mu)
    r_ref, v_ref = _two_body_dop853(r0, v0, float(dt), float(mu))
    # DOP853 at rtol 1e-12 is itself good to ~1e-11 relative over these arcs.
    assert np.linalg.norm(r - r_ref) < 1e-10 * np.linalg.norm(r_ref)
    assert np.linalg.norm(v - v_ref) < 1e-10 * np.linalg.norm(v_ref)


def test_propagation_through_periapsis_of_a_strong_hyperbola():
    """From far out on one branch (H = -8) to far out on the other (H = +7.5), where the
    universal-variable terms cancel by ~e^15; reference: the hyperbolic-anomaly closed form."""
    a, e = -0.001 * AU, 1.18
    h0, h1 = -8.0, 7.5
    mean_motion = np.sqrt(MU_SUN / abs(a) ** 3)
    dt = ((e * np.sinh(h1) - h1) - (e * np.sinh(h0) - h0)) / mean_motion
    elements = kepler.OrbitalElements(
        a, e, 0.3, 1.0, 2.0, kepler.true_anomaly_from_hyperbolic(h0, e)
    )
    r0, v0 = kepler.elements_to_state(elements, MU_SUN)
    nu1 = kepler.true_anomaly_from_hyperbolic(h1, e)
    r_ref, v_ref = kepler.elements_to_state(elements._replace(true_anomaly_rad=nu1), MU_SUN)
    r, v = jax.jit(kepler.propagate_kepler)(r0, v0, dt, MU_SUN)
    assert np.linalg.norm(r - r_ref) < 1e-11 * np.linalg.norm(r_ref)
    assert np.linalg.norm(v - v_ref) < 1e-11 * np.linalg.norm(v_ref)


def _random_elements(rng, n, hyperbolic: bool) -> kepler.OrbitalElements:
    if hyperbolic:
        e = rng.uniform(1.05, 4.0, n)
        a = -rng.uniform(0.2, 5.0, n) * AU
        nu_max = np.arccos(-1.0 / e)
        nu = rng.uniform(-0.9, 0.9, n) * nu_max
    else:
        e = rng.uniform(0.0, 0.95, n)
        a = rng.uniform(0.3, 5.0, n) * AU
        nu = rng.uniform(-np.pi, np.pi, n)
    return kepler.OrbitalElements(
        semi_major_axis=a,
        eccentricity=e,
        inclination_rad=rng.uniform(0.01, np.pi - 0.01, n),
        raan_rad=rng.uniform(0.0, 2.0 * np.pi, n),
        arg_periapsis_rad=rng.uniform(0.0, 2.0 * np.pi, n),
        true_anomaly_rad=nu,
    )


@pytest.mark.parametrize("hyperbolic", [False, True])
def test_propagation_agrees_with_kepler_equation_route(hyperbolic):
    """Universal-variable f, g against: elements -> advance M by n dt -> Kepler -> state."""
    rng = np.random.default_rng(3 + hyperbolic)
    n = 64
    elements = _random_elements(rng, n, hyperbolic)
    dt = rng.uniform(-400.0, 400.0, n) * DAY
    r0, v0 = _to_state(elements, MU_SUN)
    r, v = _propagate(r0, v0, dt, MU_SUN)

    mean_motion = np.sqrt(MU_SUN / np.abs(elements.semi_major_axis) ** 3)
    m0 = _mean_from_true(elements.true_anomaly_rad, elements.eccentricity)
    nu = _true_from_mean(m0 + mean_motion * dt, elements.eccentricity)
    r_ref, v_ref = _to_state(elements._replace(true_anomaly_rad=nu), MU_SUN)
    r_scale = np.linalg.norm(r_ref, axis=-1, keepdims=True)
    v_scale = np.linalg.norm(v_ref, axis=-1, keepdims=True)
    np.testing.assert_array_less(np.abs(r - r_ref) / r_scale, 1e-11)
    np.testing.assert_array_less(np.abs(v - v_ref) / v_scale, 1e-11)


def test_propagation_conserves_energy_and_angular_momentum_and_composes():
    rng = np.random.default_rng(5)
    n = 64
    elements = _random_elements(rng, n // 2, False)
    hyperbolas = _random_elements(rng, n // 2, True)
    elements = jax.tree.map(lambda a, b: np.concatenate([a, b]), elements, hyperbolas)
    r0, v0 = _to_state(elements, MU_SUN)
    dt1 = rng.uniform(-300.0, 300.0, n) * DAY
    dt2 = rng.uniform(-300.0, 300.0, n) * DAY
    propagate = _propagate
    r1, v1 = propagate(r0, v0, dt1, MU_SUN)
    r2, v2 = propagate(r1, v1, dt2, MU_SUN)
    r12, v12 = propagate(r0, v0, dt1 + dt2, MU_SUN)

    def energy(r, v):
        return 0.5 * np.sum(v * v, -1) - MU_SUN / np.linalg.norm(r, axis=-1)

    np.testing.assert_allclose(energy(r1, v1), energy(r0, v0), rtol=1e-12)
    np.testing.assert_allclose(np.cross(r1, v1), np.cross(r0, v0), rtol=1e-11, atol=1e3)
    scale = np.linalg.norm(r12, axis=-1, keepdims=True)
    np.testing.assert_array_less(np.abs(r2 - r12) / scale, 1e-11)
    back_r, back_v = propagate(r1, v1, -dt1, MU_SUN)
    np.testing.assert_array_less(np.abs(back_r - r0) / np.linalg.norm(r0, axis=-1)[:, None], 1e-11)
    np.testing.assert_array_less(np.abs(back_v - v0) / np.linalg.norm(v0, axis=-1)[:, None], 1e-11)


def test_propagate_kepler_zero_dt_is_identity_and_jacobian_matches_finite_differences():
    r0 = jnp.array([AU, 0.1 * AU, 0.02 * AU])
    v0 = jnp.array([-3e3, 33e3, 2e3])
    propagate = jax.jit(kepler.propagate_kepler)
    r, v = propagate(r0, v0, 0.0, MU_SUN)
    np.testing.assert_allclose(r, r0, rtol=1e-15)
    np.testing.assert_allclose(v, v0, rtol=1e-15)

    # ∂r(t)/∂v0 (a block of the state-transition matrix) by AD through the implicit χ vs
    # central differences with a 1 mm/s step.
    dt = 120 * DAY

    def final_position(dv):
        return kepler.propagate_kepler(r0, v0 + dv, dt, MU_SUN)[0]

    jac_ad = jax.jit(jax.jacfwd(final_position))(jnp.zeros(3))
    jac_rev = jax.jit(jax.jacrev(final_position))(jnp.zeros(3))
    step = 1e-3
    steps = step * jnp.concatenate([jnp.eye(3), -jnp.eye(3)])
    shifted = jax.jit(jax.vmap(final_position))(steps)
    jac_fd = np.asarray((shifted[:3] - shifted[3:]).T / (2 * step))
    np.testing.assert_allclose(jac_ad, jac_fd, rtol=1e-6, atol=1e-6 * np.abs(jac_fd).max())
    np.testing.assert_allclose(jac_rev, jac_ad, rtol=1e-12, atol=1e-9 * np.abs(jac_fd).max())


@pytest.mark.parametrize("e", [0.0, 0.01, 0.3, 0.7, 0.95, 0.999])
def test_solve_kepler_elliptic_matches_brentq(e):
    mean_anomaly = np.linspace(-20.0, 20.0, 41)
    ecc_anomaly = _solve_elliptic(mean_anomaly, e)
    for m, big_e in zip(mean_anomaly, np.asarray(ecc_anomaly), strict=True):
        ref = brentq(lambda x, m=m: x - e * np.sin(x) - m, m - 1.0, m + 1.0, xtol=1e-15)
        # Conditioning: δE = δM / (1 - e cos E), with δM ~ 1e-15 |M|.
        assert abs(big_e - ref) < 1e-13 * (1 + abs(m)) / (1.0 - e * np.cos(ref))


@pytest.mark.parametrize("e", [1.0001, 1.01, 1.5, 3.0, 20.0])
def test_solve_kepler_hyperbolic_matches_brentq(e):
    mean_anomaly = np.concatenate([-np.logspace(-4, 3, 15), np.logspace(-4, 3, 15)])
    hyp_anomaly = _solve_hyperbolic(mean_anomaly, e)
    for m, h in zip(mean_anomaly, np.asarray(hyp_anomaly), strict=True):
        lo, hi = sorted((np.arcsinh(m / e), np.arcsinh(m / (e - 1.0))))
        ref = brentq(lambda x, m=m: e * np.sinh(x) - x - m, lo, hi, xtol=1e-15, rtol=1e-15)
        assert abs(h - ref) < 1e-13 * (1 + abs(m)) / (e * np.cosh(ref) - 1.0)


def test_kepler_solvers_converge_within_their_fixed_iterations():
    """The documented margins: 7 steps suffice for 0 <= e <= 0.999999, 3 for hyperbolas."""
    mean_anomaly = np.linspace(-np.pi, np.pi, 1001)
    for e in [0.0, 0.5, 0.9, 0.99, 0.999, 0.999999]:
        fast = _solve_elliptic(mean_anomaly, e, n_iter=7)
        slow = _solve_elliptic(mean_anomaly, e, n_iter=60)
        np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-14)
    mean_anomaly = np.concatenate([-np.logspace(-8, 4, 300), np.logspace(-8, 4, 300)])
    for e in [1.000001, 1.001, 1.1, 2.0, 100.0]:
        fast = _solve_hyperbolic(mean_anomaly, e, n_iter=3)
        slow = _solve_hyperbolic(mean_anomaly, e, n_iter=200)
        np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=1e-12)


def test_universal_solve_converges_within_its_fixed_iterations():
    """The documented budget: near-parabolic arcs (the slowest) converge in 20 of the 30 steps."""
    rng = np.random.default_rng(12)
    n = 64
    eccentricity = 1.0 + rng.choice([-1.0, 1.0], n) * rng.uniform(1e-9, 1e-3, n)
    elements = kepler.OrbitalElements(
        semi_major_axis=np.sign(1.0 - eccentricity) * 1e3 * AU,
        eccentricity=eccentricity,
        inclination_rad=rng.uniform(0.0, 3.0, n),
        raan_rad=rng.uniform(0.0, 6.0, n),
        arg_periapsis_rad=rng.uniform(0.0, 6.0, n),
        true_anomaly_rad=rng.uniform(-2.5, 2.5, n),
    )
    r0, v0 = _to_state(elements, MU_SUN)
    dt = rng.uniform(-3000.0, 3000.0, n) * DAY
    batched = jax.vmap(
        functools.partial(kepler.propagate_kepler, n_iter=20), in_axes=(0, 0, 0, None)
    )
    r20, _ = jax.jit(batched)(r0, v0, dt, MU_SUN)
    r_default, _ = _propagate(r0, v0, dt, MU_SUN)
    scale = np.linalg.norm(r_default, axis=-1, keepdims=True)
    np.testing.assert_array_less(np.abs(r20 - r_default) / scale, 1e-13)
    assert kepler.UNIVERSAL_ITERATIONS >= 20


def test_anomaly_conversions_invert_each_other():
    rng = np.random.default_rng(9)
    e = rng.uniform(0.0, 0.99, 200)
    nu = rng.uniform(-np.pi, np.pi, 200)
    np.testing.assert_allclose(
        kepler.true_anomaly_from_eccentric(kepler.eccentric_anomaly_from_true(nu, e), e),
        nu,
        atol=1e-12,
    )
    m = _mean_from_true(nu, e)
    np.testing.assert_allclose(_true_from_mean(m, e), nu, atol=1e-9)
    e_h = rng.uniform(1.01, 5.0, 200)
    nu_h = rng.uniform(-0.95, 0.95, 200) * np.arccos(-1.0 / e_h)
    m_h = _mean_from_true(nu_h, e_h)
    np.testing.assert_allclose(_true_from_mean(m_h, e_h), nu_h, atol=1e-10)
    # Independent closed form: tan(ν/2) = sqrt((1+e)/(1-e)) tan(E/2).
    big_e = kepler.eccentric_anomaly_from_true(nu, e)
    np.testing.assert_allclose(
        np.tan(nu / 2), np.sqrt((1 + e) / (1 - e)) * np.tan(np.asarray(big_e) / 2), rtol=1e-9
    )


def _elements_by_numpy(r, v, mu):
    """Textbook RV2COE written with arccos (Curtis 2014, algorithm 4.2) as an independent oracle."""
    h = np.cross(r, v)
    node = np.cross([0.0, 0.0, 1.0], h)
    e_vec = ((v @ v - mu / np.linalg.norm(r)) * r - (r @ v) * v) / mu
    e = np.linalg.norm(e_vec)
    a = 1.0 / (2.0 / np.linalg.norm(r) - v @ v / mu)
    i = np.arccos(h[2] / np.linalg.norm(h))
    raan = np.arccos(node[0] / np.linalg.norm(node))
    raan = raan if node[1] >= 0 else 2 * np.pi - raan
    argp = np.arccos(node @ e_vec / (np.linalg.norm(node) * e))
    argp = argp if e_vec[2] >= 0 else 2 * np.pi - argp
    nu = np.arccos(np.clip(e_vec @ r / (e * np.linalg.norm(r)), -1, 1))
    nu = nu if r @ v >= 0 else -nu
    return a, e, i, raan, argp, nu


@pytest.mark.parametrize("hyperbolic", [False, True])
def test_state_to_elements_matches_textbook_and_round_trips(hyperbolic):
    rng = np.random.default_rng(21 + hyperbolic)
    elements = _random_elements(rng, 64, hyperbolic)
    r, v = _to_state(elements, MU_SUN)
    back = _to_elements(r, v, MU_SUN)
    np.testing.assert_allclose(back.semi_major_axis, elements.semi_major_axis, rtol=1e-11)
    np.testing.assert_allclose(back.eccentricity, elements.eccentricity, rtol=1e-10, atol=1e-12)
    for name in ("inclination_rad", "raan_rad", "arg_periapsis_rad", "true_anomaly_rad"):
        diff = np.angle(np.exp(1j * (getattr(back, name) - getattr(elements, name))))
        np.testing.assert_array_less(np.abs(diff), 1e-9)
    for k in range(10):
        ref = _elements_by_numpy(np.asarray(r[k]), np.asarray(v[k]), MU_SUN)
        got = [float(x[k]) for x in back]
        np.testing.assert_allclose(got[:2], ref[:2], rtol=1e-10)
        np.testing.assert_allclose(np.cos(got[2:]), np.cos(ref[2:]), atol=1e-8)
        np.testing.assert_allclose(np.sin(got[2:]), np.sin(ref[2:]), atol=1e-8)


def test_state_to_elements_singular_conventions():
    # Circular equatorial: node along +x, periapsis at the node, ν = true longitude.
    angle = 0.7
    r = 7000e3 * np.array([np.cos(angle), np.sin(angle), 0.0])
    v = np.sqrt(MU_EARTH / 7000e3) * np.array([-np.sin(angle), np.cos(angle), 0.0])
    el = kepler.state_to_elements(r, v, MU_EARTH)
    assert float(el.eccentricity) < 1e-12
    assert float(el.inclination_rad) == pytest.approx(0.0, abs=1e-15)
    assert float(el.raan_rad) == 0.0 and float(el.arg_periapsis_rad) == 0.0
    assert float(el.true_anomaly_rad) == pytest.approx(angle, abs=1e-12)
    r_back, v_back = kepler.elements_to_state(el, MU_EARTH)
    np.testing.assert_allclose(r_back, r, rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(v_back, v, rtol=1e-12, atol=1e-9)


def test_time_since_periapsis_lands_on_periapsis():
    """Seed 001 eqs. 27-30: propagating back by t - τ reaches r·v = 0 at r = a(1 - e)."""
    rng = np.random.default_rng(2)
    for hyperbolic in (False, True):
        elements = _random_elements(rng, 64, hyperbolic)
        r, v = _to_state(elements, MU_SUN)
        t_peri = jax.jit(jax.vmap(kepler.time_since_periapsis, in_axes=(0, 0, None)))(r, v, MU_SUN)
        rp, vp = _propagate(r, v, -t_peri, MU_SUN)
        r_periapsis = elements.semi_major_axis * (1 - elements.eccentricity)
        np.testing.assert_allclose(np.linalg.norm(rp, axis=-1), r_periapsis, rtol=1e-10)
        radial_speed = np.sum(rp * vp, -1) / np.linalg.norm(rp, axis=-1)
        np.testing.assert_array_less(np.abs(radial_speed), 1e-7 * np.linalg.norm(vp, axis=-1))


def test_stumpff_functions_match_closed_forms_in_high_precision():
    mpmath = pytest.importorskip("mpmath")
    mpmath.mp.dps = 40
    psi = np.concatenate([-np.logspace(-8, 3, 40), [0.0], np.logspace(-8, 3, 40), [-1.0, 1.0]])
    c2s = jax.jit(kepler.stumpff_c2)(psi)
    c3s = jax.jit(kepler.stumpff_c3)(psi)
    for x, c2, c3 in zip(psi, c2s, c3s, strict=True):
        p = mpmath.mpf(float(x))
        if p == 0:
            ref2, ref3 = mpmath.mpf(1) / 2, mpmath.mpf(1) / 6
        elif p > 0:
            s = mpmath.sqrt(p)
            ref2, ref3 = (1 - mpmath.cos(s)) / p, (s - mpmath.sin(s)) / s**3
        else:
            s = mpmath.sqrt(-p)
            ref2, ref3 = (mpmath.cosh(s) - 1) / (-p), (mpmath.sinh(s) - s) / s**3
        assert float(c2) == pytest.approx(float(ref2), rel=1e-14)
        assert float(c3) == pytest.approx(float(ref3), rel=1e-14)


def test_vmapped_propagation_matches_per_run_loop_and_traces_once():
    rng = np.random.default_rng(8)
    elements = _random_elements(rng, 64, False)
    r0, v0 = _to_state(elements, MU_SUN)
    dt = rng.uniform(0.0, 300.0, 64) * DAY

    @eqx.debug.assert_max_traces(max_traces=1)
    def batch(r0, v0, dt):
        return jax.vmap(kepler.propagate_kepler, in_axes=(0, 0, 0, None))(r0, v0, dt, MU_SUN)

    batch = jax.jit(batch)
    r, v = batch(r0, v0, dt)
    batch(r0, v0, dt + 1.0)  # same shapes: no retrace
    single = jax.jit(kepler.propagate_kepler)
    for k in range(0, 64, 8):
        rk, vk = single(r0[k], v0[k], dt[k], MU_SUN)
        np.testing.assert_allclose(r[k], rk, rtol=1e-13)
        np.testing.assert_allclose(v[k], vk, rtol=1e-13)
