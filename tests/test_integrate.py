"""Fixed-step RK4 of the impactor dynamics against scipy's DOP853; the adaptive solves'
cheaper-compiled diffrax loop against diffrax's own."""

import diffrax
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from packaging.version import Version
from scipy.integrate import solve_ivp

from gnc_jax import integrate
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


def _adaptive_solve(adjoint, event=False):
    """A batched adaptive Dopri8 solve of a forced oscillator to a traced end time (either
    direction), with a stopping event; the values and their forward-mode derivatives."""

    def field(t, y, args):
        return jnp.stack([y[1], -args * y[0] + 0.3 * jnp.sin(t)])

    stop = diffrax.Event(lambda t, y, args, **kw: y[0] - 1.2) if event else None

    def solve(t1, y0, w):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            diffrax.Dopri8(),
            t0=0.0,
            t1=t1,
            dt0=None,
            y0=y0,
            args=w,
            stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12),
            event=stop,
            adjoint=adjoint,
            saveat=diffrax.SaveAt(t1=True),
            throw=False,
        )
        return sol.ts[-1], sol.ys[-1], sol.stats["num_steps"]

    def with_tangent(t1, y0, w):
        out, tangent = jax.jvp(lambda w: solve(t1, y0, w)[1], (w,), (jnp.ones_like(w),))
        return solve(t1, y0, w), tangent

    return jax.jit(jax.vmap(with_tangent))


def test_the_adaptive_loop_is_diffraxs_bit_for_bit_with_one_clip_floor_compiled():
    """gnc_jax's ``ForwardMode`` flies diffrax's own loop with its t1 - 100 ulp threshold
    computed in a ``fori_loop``: the same end times, states, step counts and derivatives bit
    for bit, forward and backward in time, with and without an event; the compiled solve has
    ``nextafter`` once where diffrax's has a hundred per solve (the solve otherwise unchanged).
    The versions read for it must take it (a later diffrax with another loop falls back to its
    own, which the equality then checks trivially)."""
    active = integrate._LOOP is not diffrax._integrate.loop
    if Version(diffrax.__version__) <= Version("0.7.2"):
        assert active, "diffrax's loop source no longer matches: the clip floor is compiled whole"
    # the threshold itself, at the edges too (zero, subnormals, infinities, NaN)
    edges = jnp.array([0.0, -0.0, 5e-324, -1e-310, 2.2250738585072014e-308, 1.0, -1.0, 2.4e8])
    edges = jnp.concatenate([edges, jnp.array([1.7976931348623157e308, jnp.inf, -jnp.inf])])
    chained = edges
    for _ in range(100):
        chained = eqxi.prevbefore(chained)
    looped = jax.jit(integrate._prevbefore_times(100))(edges)
    np.testing.assert_array_equal(
        np.asarray(looped).view(np.int64), np.asarray(chained).view(np.int64)
    )
    t1 = jnp.array([4.0, 7.5, -3.0, 1e-3, 9.0])
    y0 = jnp.array([[1.0, 0.0], [0.5, 0.2], [1.0, -0.1], [0.0, 1.0], [1.0, 0.5]])
    w = jnp.array([1.0, 2.0, 0.5, 1.5, 3.0])
    for event in (False, True):
        ours = _adaptive_solve(integrate.ForwardMode(), event)
        theirs = _adaptive_solve(diffrax.ForwardMode(), event)
        got, want = ours(t1, y0, w), theirs(t1, y0, w)
        for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        count = lambda f: f.lower(t1, y0, w).as_text().count("next_after")  # noqa: E731
        n_ours, n_theirs = count(ours), count(theirs)  # a chain per solve traced (value, jvp)
        assert (n_theirs >= 100 * n_ours >= 100) if active else (n_ours == n_theirs), n_ours
