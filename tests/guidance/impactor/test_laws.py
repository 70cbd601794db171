"""Impactor guidance laws: switching curves, hysteresis, thrust direction, predictive burns."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax.dynamics.impactor import (
    Engine,
    ImpactorState,
    RelativeDynamics,
    coast_to_b_plane,
    propagate,
)
from gnc_jax.geometry import b_plane_frame, los_rate, range_rate, unforced_miss
from gnc_jax.guidance import (
    ImpactorGuidanceContext,
    LOSGuidanceState,
    LOSSwitchingCurveGuidance,
    PredictiveGuidance,
    switching_curve,
)
from gnc_jax.guidance.impactor.los import miss_limits
from gnc_jax.navigation import NavEstimate


def context(**kw):
    c = b_plane_frame(jnp.array([-1.0, 0.0, 0.0]), jnp.array([0.0, 0.0, 1.0]))
    base = dict(
        c_bi=c,
        aim_initial_m=jnp.zeros(2),
        aim_final_m=jnp.array([1e3, 3e3]),
        retarget_time_s=jnp.asarray(6450.0),
        cutoff_time_s=jnp.asarray(7140.0),
        engine=Engine(jnp.asarray(88.0), jnp.asarray(230.0)),
        mass_kg=jnp.asarray(372.0),
        dynamics=RelativeDynamics(jnp.asarray(0.0), jnp.asarray(0.0), jnp.array([1.0, 0, 0])),
        dt_s=1.0,
        image_interval_s=15.0,
    )
    base.update(kw)
    return ImpactorGuidanceContext(**base)


def nav_at(r, v, p=None):
    return NavEstimate(
        jnp.concatenate([jnp.asarray(r), jnp.asarray(v)]), jnp.eye(6) * 1e4 if p is None else p
    )


def test_switching_curve_is_the_los_rate_of_the_tolerated_miss():
    rng = np.random.default_rng(0)
    for _ in range(20):
        rho = np.array([rng.uniform(1e5, 7e7), 0.0, 0.0])
        rho_limit = rng.uniform(10.0, 1e4)
        rdot = -rng.uniform(1e3, 2e4)
        w = float(switching_curve(rho[0], rdot, rho_limit))
        # a geometry with exactly that LOS rate has unforced miss rho_limit (eq. 7 inverted)
        rho_dot = np.array([rdot, w * rho[0], 0.0])
        assert float(unforced_miss(jnp.asarray(rho), jnp.asarray(rho_dot))) == pytest.approx(
            rho_limit, rel=1e-9
        )
    assert np.isinf(float(switching_curve(100.0, -1e4, 200.0)))


@pytest.mark.parametrize("seed", range(5))
def test_thrust_direction_reduces_los_rate(seed):
    rng = np.random.default_rng(seed)
    ctx = context(retarget_time_s=jnp.asarray(1e9))
    r = np.array([rng.uniform(1e6, 7e7), rng.normal() * 1e4, rng.normal() * 1e4])
    v = np.array([-1.02e4, rng.normal() * 0.5, rng.normal() * 0.5])
    law = LOSSwitchingCurveGuidance()
    state = LOSGuidanceState(*(jnp.zeros(()) for _ in range(5)))._replace(
        sigma_b_m=jnp.asarray(1.0)
    )
    cmd, _ = law.step(state, nav_at(r, v), 0.0, ctx)
    n = np.asarray(cmd.direction)
    assert float(cmd.throttle) == 1.0  # 1 m sigma: any sizeable miss opens the engine
    omega = lambda vv: np.linalg.norm(np.asarray(los_rate(jnp.asarray(-r), jnp.asarray(-vv))))
    dv = 0.05
    assert omega(v + dv * n) < omega(v)
    assert omega(v - dv * n) > omega(v)  # the opposite sign (eq. 19 as printed) increases it
    assert abs(n @ v) < 1e-9 * np.linalg.norm(v)  # perpendicular to the relative velocity


def test_hysteresis_logic():
    ctx = context(retarget_time_s=jnp.asarray(1e9))
    law = LOSSwitchingCurveGuidance(k1=jnp.asarray(4.0), k2=jnp.asarray(1.0))
    r = np.array([5e7, 0.0, 0.0])
    sigma = 1000.0  # k2 sigma above the engine-resolution floor (~580 m here, see below)
    rdot = -1.02e4
    w_open = float(switching_curve(5e7, rdot, 4000.0))
    w_close = float(switching_curve(5e7, rdot, 1000.0))

    def run(omega, prev):
        v = np.array([rdot, -omega * 5e7, 0.0])  # rho = -r, rho_dot = -v
        st = LOSGuidanceState(jnp.asarray(prev), jnp.asarray(sigma), *(jnp.zeros(()),) * 3)
        cmd, new = law.step(st, nav_at(r, v), 0.0, ctx)
        return float(cmd.throttle)

    mid = 0.5 * (w_open + w_close)
    assert run(1.01 * w_open, 0.0) == 1.0
    assert run(mid, 0.0) == 0.0
    assert run(mid, 1.0) == 1.0
    assert run(0.99 * w_close, 1.0) == 0.0
    # no burn after the cut-off time
    st = LOSGuidanceState(jnp.asarray(0.0), jnp.asarray(sigma), *(jnp.zeros(()),) * 3)
    cmd, _ = law.step(st, nav_at(r, np.array([rdot, -2 * w_open * 5e7, 0])), 7200.0, ctx)
    assert float(cmd.throttle) == 0.0


def test_shut_off_tolerance_has_the_engine_resolution_as_floor():
    # One control step of thrust moves the predicted miss by (T/m) dt t_go; the shut-off
    # tolerance never goes below half of it (with sigma_B -> 0 the engine could never close),
    # and the opening tolerance stays k1/k2 times the shut-off one (a closed band toggles the
    # engine every few steps: see test_a_perfect_sensor_keeps_navigation).
    ctx = context(retarget_time_s=jnp.asarray(1e9))
    r, v = np.array([5e7, 0.0, 0.0]), np.array([-1.02e4, 0.0, 0.0])
    nav = nav_at(r, v)
    t_go = 5e7 / 1.02e4
    half_step = 0.5 * float(ctx.engine.thrust_n / ctx.mass_kg) * ctx.dt_s * t_go
    for k2 in (1.0, 2.0):
        for sigma in (0.0, 1.0, 100.0, 2e3):
            lo, hi = miss_limits(4.0, k2, sigma, 5e7, nav, ctx)
            assert float(lo) == pytest.approx(max(k2 * sigma, half_step))
            assert float(hi) == pytest.approx(4.0 / k2 * max(k2 * sigma, half_step))
    lo, hi = miss_limits(4.0, 1.0, 1e4, 5e7, nav, ctx)  # a paper-like sigma: the paper's levels
    assert (float(lo), float(hi)) == (1e4, 4e4)


def test_relaxed_switch_tends_to_the_hard_logic():
    ctx = context(retarget_time_s=jnp.asarray(1e9))
    r = np.array([5e7, 0.0, 0.0])
    w_open = float(switching_curve(5e7, -1.02e4, 4000.0))
    for omega, prev, expected in (
        (1.2 * w_open, 0.0, 1.0),
        (0.8 * w_open, 0.0, 0.0),
        (0.8 * w_open, 1.0, 1.0),
        (0.1 * w_open, 1.0, 0.0),
    ):
        v = np.array([-1.02e4, -omega * 5e7, 0.0])
        st = LOSGuidanceState(jnp.asarray(prev), jnp.asarray(1000.0), *(jnp.zeros(()),) * 3)
        law = LOSSwitchingCurveGuidance(temperature=jnp.asarray(1e-3), relaxed=True)
        cmd, _ = law.step(st, nav_at(r, v), 0.0, ctx)
        assert float(cmd.throttle) == pytest.approx(expected, abs=1e-6)


def test_los_plan_uses_the_mapped_covariance():
    ctx = context()
    p = jnp.diag(jnp.array([1e10, 4e6, 9e6, 1e-2, 1e-2, 1e-2]))
    r, v = np.array([7.344e7, 0, 0]), np.array([-1.02e4, 0, 0])
    st = LOSSwitchingCurveGuidance().init(nav_at(r, v, p), ctx)
    t_go = 7200.0
    expected = np.sqrt(4e6 + 9e6 + 2 * t_go**2 * 1e-2)
    assert float(st.sigma_b_m) == pytest.approx(expected, rel=1e-9)


def test_predictive_burn_nulls_the_predicted_miss():
    ctx = context()
    law = PredictiveGuidance(burn_times_s=jnp.array([1200.0]))
    r = np.array([7.344e7 - 1.02e4 * 1195.0, 4e3, -7e3])
    v = np.array([-1.02e4, 0.3, -0.1])
    nav = nav_at(r, v)
    state = law.plan(law.init(nav, ctx), nav, 1195.0, ctx)
    assert float(state.burn_start_s) == 1200.0
    assert float(state.predicted_miss_m) == pytest.approx(
        np.hypot(
            *np.asarray(
                coast_to_b_plane(
                    ctx.dynamics, ImpactorState(jnp.asarray(r), jnp.asarray(v), 372.0), ctx.c_bi, 1
                )[0]
            )
        ),
        rel=1e-6,
    )
    # Execute the commanded finite burn exactly and coast: the B-plane point is the aim point.
    y = ImpactorState(jnp.asarray(r), jnp.asarray(v), jnp.asarray(372.0))
    y = propagate(ctx.dynamics, y, jnp.zeros(3), 0.0, 5.0, 1)
    thrust = ctx.engine.thrust_n * state.burn_direction
    y = propagate(ctx.dynamics, y, thrust, ctx.engine.mass_flow(1.0), state.burn_duration_s, 200)
    b, _ = coast_to_b_plane(ctx.dynamics, y, ctx.c_bi, 1)
    assert np.linalg.norm(np.asarray(b)) < 1.0  # aim (0, 0) before the retarget; mass flow ~cm
    t_go = 7.344e7 / 1.02e4 - 1200.0  # impulsive straight-line estimate: |miss| / t_go
    assert float(state.burn_dv_mps) == pytest.approx(float(state.predicted_miss_m) / t_go, rel=0.01)


def test_predictive_burn_reports_the_miss_its_solve_leaves():
    """The Newton solve's residual, predicted again at the solution: nanometres for the
    packaged engine (converged), kilometres for an engine whose burn outlasts the approach."""
    ctx = context()
    r = np.array([7.344e7 - 1.02e4 * 1195.0, 4e3, -7e3])
    v = np.array([-1.02e4, 0.3, -0.1])
    nav = nav_at(r, v)
    law = PredictiveGuidance(burn_times_s=jnp.array([1200.0]))
    state = law.plan(law.init(nav, ctx), nav, 1195.0, ctx)
    assert float(state.residual_m) < 1e-4 and bool(law.converged(state))
    weak = eqx.tree_at(lambda c: c.engine.thrust_n, ctx, jnp.asarray(0.05))
    state = law.plan(law.init(nav, weak), nav, 1195.0, weak)
    assert float(state.burn_duration_s) > 1e4  # longer than the 6000 s left
    assert float(state.residual_m) > 1e3 and not bool(law.converged(state))
    nan = state._replace(residual_m=jnp.asarray(jnp.nan))
    assert not bool(law.converged(nan))
    # converged, but the 7 s burn from 1200 s would end after a cut-off at 1203 s: not flown
    early = eqx.tree_at(lambda c: c.cutoff_time_s, ctx, jnp.asarray(1203.0))
    state = law.plan(law.init(nav, early), nav, 1195.0, early)
    assert 3.0 < float(state.burn_duration_s) < 20.0
    assert not bool(law.converged(state))


def test_predictive_throttle_covers_the_burn_exactly():
    ctx = context()
    law = PredictiveGuidance()
    st = law.init(None, ctx)._replace(
        burn_start_s=jnp.asarray(10.3), burn_duration_s=jnp.asarray(2.5)
    )
    total = 0.0
    for k in range(20):
        cmd, st = law.step(st, None, float(k), ctx)
        total += float(cmd.throttle) * ctx.dt_s
    assert total == pytest.approx(2.5, abs=1e-12)


def test_laws_are_differentiable_in_their_gains():
    ctx = context(retarget_time_s=jnp.asarray(1e9))
    w_open = float(switching_curve(5e7, -1.02e4, 4000.0))  # sigma_B above the resolution floor
    r, v = np.array([5e7, 0.0, 0.0]), np.array([-1.02e4, -1.02 * w_open * 5e7, 0.0])
    st = LOSGuidanceState(jnp.asarray(0.3), jnp.asarray(1000.0), *(jnp.zeros(()),) * 3)

    def throttle(k1):
        law = LOSSwitchingCurveGuidance(k1=k1, temperature=jnp.asarray(0.05), relaxed=True)
        return law.step(st, nav_at(r, v), 0.0, ctx)[0].throttle

    g = jax.grad(throttle)(jnp.asarray(4.0))
    h = 1e-5
    fd = (throttle(jnp.asarray(4.0 + h)) - throttle(jnp.asarray(4.0 - h))) / (2 * h)
    assert float(g) == pytest.approx(float(fd), rel=1e-6)
    assert float(g) < 0.0  # a larger tolerance opens the engine less
    assert float(range_rate(jnp.asarray(-r), jnp.asarray(-v))) < 0


def test_square_root_free_switch_decides_as_the_switching_curves():
    """The hard LOS switch (multiplied-out squares) against schmitt_trigger on the rates of
    eq. 20, over random geometries: closing and opening ranges, ranges inside the tolerance,
    both previous states, and sigma_B small enough for the one-step resolution to bind."""
    from gnc_jax.guidance.impactor.los import _hard_switch
    from gnc_jax.guidance.trigger import schmitt_trigger

    ctx = context()
    rng = np.random.default_rng(3)
    n = 4000
    # LOS along x, the miss made by the transverse velocity below
    rho = np.zeros((n, 3))
    rho[:, 0] = 10.0 ** rng.uniform(2.0, np.log10(7e7), size=n)
    rho_n = rho[:, 0]
    sigma = 10.0 ** rng.uniform(-3, 4, size=n)
    # Closing at 10.2 km/s with an unforced miss near the tolerances (k2 sigma_B, k1 sigma_B or
    # the one-step resolution 0.118 m/s^2 x 1 s x t_go / 2), so that the decisions depend on
    # each limit; some ranges opening, some slow.
    resolution = 0.5 * 88.0 / 372.0 * rho_n / 1.02e4
    limit = np.maximum(rng.choice([1.0, 4.0], size=n) * sigma, resolution)
    miss = limit * 10.0 ** rng.uniform(-0.3, 0.3, size=n)
    angle = rng.uniform(0.0, 2.0 * np.pi, size=n)
    perpendicular = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    v = np.zeros((n, 3))
    v[:, 0] = 1.02e4  # the impactor at r = -rho, moving towards the target
    v[:, 1:] = (miss * 1.02e4 / rho_n)[:, None] * perpendicular
    v[: n // 10] *= -1.0
    v[n // 10 : n // 5] *= 1e-3
    prev = rng.integers(0, 2, size=n).astype(float)
    law = LOSSwitchingCurveGuidance(jnp.asarray(4.0), jnp.asarray(1.0))

    def both(rho, v, sigma, prev):
        nav = nav_at(-rho, v)  # aim point at the origin: rho = -r
        state = LOSGuidanceState(jnp.asarray(prev), jnp.asarray(sigma), 0.0, 0.0, 0.0)
        rho_dot = -nav.v
        rho_n = jnp.linalg.norm(rho)
        rdot = range_rate(rho, rho_dot)
        omega = jnp.linalg.norm(los_rate(rho, rho_dot))
        lo, hi = miss_limits(law.k1, law.k2, state.sigma_b_m, rho_n, nav, ctx)
        ref = schmitt_trigger(
            omega,
            state.engine_on,
            switching_curve(rho_n, rdot, hi),
            switching_curve(rho_n, rdot, lo),
        )
        return ref, _hard_switch(rho, rho_dot, state, nav, law.k1, law.k2, ctx)

    ref, fast = jax.vmap(both)(
        jnp.asarray(rho), jnp.asarray(v), jnp.asarray(sigma), jnp.asarray(prev)
    )
    ref, fast = np.asarray(ref), np.asarray(fast)
    # every kind of decision occurs: open, close and hold
    assert 0.05 < ref.mean() < 0.95 and (ref != prev).any() and (ref == prev).any()
    np.testing.assert_array_equal(fast, ref)
