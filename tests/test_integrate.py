"""Fixed-step RK4 of the impactor dynamics against scipy's DOP853."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gnc_jax.dynamics.impactor import (
    Engine,
    ImpactorState,
    RelativeDynamics,
    propagate,
    vector_field,
)


def test_rk4_matches_dop853_with_gravity_tide_and_thrust():
    # A strong (exaggerated) target gravity and solar tide so that the check is not trivial.
    dyn = RelativeDynamics(jnp.asarray(5e9), jnp.asarray(1e-9), jnp.array([0.6, 0.8, 0.0]))
    eng = Engine(jnp.asarray(88.0), jnp.asarray(230.0))
    thrust = jnp.array([0.0, 88.0, 0.0])
    flow = eng.mass_flow(1.0)
    y0 = ImpactorState(
        jnp.array([2.0e6, 1e4, -3e4]), jnp.array([-1.0e3, 5.0, 2.0]), jnp.asarray(372.0)
    )
    duration = 1500.0
    y = propagate(dyn, y0, thrust, flow, duration, 1500)

    def f(t, s):
        d = vector_field(t, ImpactorState(s[:3], s[3:6], s[6]), (dyn, thrust, flow))
        return np.concatenate([np.asarray(d.r), np.asarray(d.v), [float(d.m)]])

    s0 = np.concatenate([np.asarray(y0.r), np.asarray(y0.v), [372.0]])
    ref = solve_ivp(f, (0.0, duration), s0, method="DOP853", rtol=1e-13, atol=1e-9).y[:, -1]
    np.testing.assert_allclose(np.asarray(y.r), ref[:3], rtol=0, atol=1e-4)
    np.testing.assert_allclose(np.asarray(y.v), ref[3:6], rtol=0, atol=1e-7)
    assert float(y.m) == pytest.approx(ref[6], rel=1e-12)
    # Fourth order: halving the step divides the error by about 16.
    coarse = propagate(dyn, y0, thrust, flow, duration, 50)
    fine = propagate(dyn, y0, thrust, flow, duration, 100)
    e1 = np.linalg.norm(np.asarray(coarse.r) - ref[:3])
    e2 = np.linalg.norm(np.asarray(fine.r) - ref[:3])
    assert 10.0 < e1 / e2 < 22.0


def test_straight_line_with_constant_thrust_is_exact():
    dyn = RelativeDynamics(jnp.asarray(0.0), jnp.asarray(0.0), jnp.array([1.0, 0, 0]))
    y0 = ImpactorState(jnp.array([1e7, 0.0, 0.0]), jnp.array([-1e4, 0.0, 0.0]), jnp.asarray(100.0))
    thrust = jnp.array([0.0, 0.0, 10.0])
    y = propagate(dyn, y0, thrust, 0.0, 30.0, 1)
    np.testing.assert_allclose(np.asarray(y.r), [1e7 - 3e5, 0.0, 0.5 * 0.1 * 900.0], rtol=1e-14)
    assert jax.numpy.isfinite(y.m)


@pytest.mark.parametrize("tableau", ["rk4", "rk6"])
def test_convergence_order_of_the_tableaus(tableau):
    """Observed order on a smooth nonlinear problem (Kepler orbit) vs the closed form."""
    from gnc_jax.integrate import RK4, RK6_BUTCHER, integrate_fixed

    tab = {"rk4": RK4, "rk6": RK6_BUTCHER}[tableau]

    def f(t, y, args):
        r = y[:2]
        return jnp.concatenate([y[2:], -r / jnp.linalg.norm(r) ** 3])

    y0 = jnp.array([1.0, 0.0, 0.0, 1.0])  # circular orbit, period 2 pi
    exact = np.array([np.cos(3.0), np.sin(3.0)])
    errs = []
    for n in (40, 80):
        y = integrate_fixed(f, 0.0, y0, 3.0 / n, n, tableau=tab)
        errs.append(np.linalg.norm(np.asarray(y[:2]) - exact))
    order = np.log2(errs[0] / errs[1])
    assert order == pytest.approx(tab.order, abs=0.35)


@pytest.mark.parametrize("mu,tide", [(0.0, 0.0), (5e9, 0.0), (0.0, 1e-9), (5e9, 1e-9)])
def test_terms_left_out_when_zero_give_the_same_bits(mu, tide):
    """RelativeDynamics.of computes only the nonzero terms; the step equals the one that
    computes every term (adding exact zeros) bit for bit, with thrust and without."""
    from gnc_jax.dynamics.impactor import rk4

    sun = jnp.array([0.6, 0.8, 0.0])
    every = RelativeDynamics(jnp.asarray(mu), jnp.asarray(tide), sun)
    needed = RelativeDynamics.of(mu, tide, sun)
    assert (needed.point_mass, needed.tide) == (mu != 0.0, tide != 0.0)
    y0 = ImpactorState(
        jnp.array([7e6, -3e5, 2e4]), jnp.array([-1e4, 3.0, -1.0]), jnp.asarray(372.0)
    )
    for thrust, flow in ((jnp.zeros(3), 0.0), (jnp.array([10.0, -60.0, 40.0]), 0.04)):
        a = jax.jit(rk4)(every, y0, thrust, flow, 1.0)
        b = jax.jit(rk4)(needed, y0, thrust, flow, 1.0)
        for x, y in zip(a, b):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
        np.testing.assert_array_equal(
            np.asarray(every.gravity(y0.r)), np.asarray(needed.gravity(y0.r))
        )
