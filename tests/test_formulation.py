"""The batched-CPU formulation of the closed loops against independent references.

The closed loops draw per image instead of per step, integrate the accelerometer's white
noise over an image interval in closed form, tilt the thrust by a 3-axis pointing draw, compute
the LOS Jacobian in closed form and force values into memory with ``computed_once``. Each is
checked here against brute force (per-step sampling), ``jax.jacfwd`` or the plain function.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax._numerics import computed_once, matmul
from gnc_jax.dynamics.impactor import tilt_direction
from gnc_jax.navigation.ekf import NavEstimate, los_model, predict_los, predict_measurement
from gnc_jax.systems.impactor.navigation import accel_noise


def test_computed_once_is_the_function_with_its_derivatives():
    def fn(a, b):
        return jnp.sin(a) * b, {"c": a**3 + b}

    a, b = jnp.asarray(0.7), jnp.asarray(-1.3)
    live = jnp.asarray(2.0)
    np.testing.assert_allclose(computed_once(fn, live, a, b)[0], fn(a, b)[0], rtol=0)
    once = lambda a, b: computed_once(fn, live, a, b)[1]["c"] * computed_once(fn, live, a, b)[0]
    plain = lambda a, b: fn(a, b)[1]["c"] * fn(a, b)[0]
    g1, g2 = jax.grad(once, argnums=(0, 1))(a, b), jax.grad(plain, argnums=(0, 1))(a, b)
    np.testing.assert_allclose(np.array(g1), np.array(g2), rtol=1e-14)
    j1 = jax.jvp(once, (a, b), (jnp.asarray(1.0), jnp.asarray(0.5)))[1]
    j2 = jax.jvp(plain, (a, b), (jnp.asarray(1.0), jnp.asarray(0.5)))[1]
    np.testing.assert_allclose(j1, j2, rtol=1e-14)
    # under jit and vmap, with a traced trip-count source
    xs = jnp.linspace(0.0, 1.0, 5)
    got = jax.jit(jax.vmap(lambda x, t: computed_once(fn, t, x, b)[0], in_axes=(0, None)))(xs, live)
    np.testing.assert_allclose(got, jax.vmap(lambda x: fn(x, b)[0])(xs), rtol=0)


def test_computed_once_reverse_mode_rules_are_the_functions_gradient():
    """``adjoint="recompute"`` and ``"save"``: the plain function's value and gradient, through
    a traced gain the function closes over (between constant arrays), an integer argument, a
    random draw, an unused output, under vmap, scan and checkpoint."""
    key, offset, scale = jax.random.key(3), jnp.asarray([0.2]), jnp.asarray([1.1])

    def objective(gain, x0, adjoint):
        def step(carry, t):
            x, n = carry

            def fn(x, n):
                w = jax.random.normal(jax.random.fold_in(key, n))
                y = jnp.sin(gain * (x + offset[0])) * scale[0] + 0.1 * w * x
                return {"x": y, "n": n + 1, "unused": gain * x}

            out = fn(x, n) if adjoint is None else computed_once(fn, t, x, n, adjoint=adjoint)
            return (out["x"], out["n"]), None

        def one(x):
            (x, _), _ = jax.lax.scan(jax.checkpoint(step), (x, jnp.int32(0)), jnp.arange(4.0))
            return x

        return jnp.sum(jax.vmap(one)(x0) ** 2)

    gain, x0 = jnp.asarray(1.3), jnp.linspace(0.2, 0.9, 3)
    grad = jax.jit(jax.value_and_grad(objective, argnums=(0, 1)), static_argnums=2)
    value, (g_gain, g_x0) = grad(gain, x0, None)
    assert abs(float(g_gain)) > 0.01
    for adjoint in ("recompute", "save"):
        v, (gg, gx) = grad(gain, x0, adjoint)
        np.testing.assert_allclose(v, value, rtol=0, err_msg=adjoint)
        np.testing.assert_allclose(gg, g_gain, rtol=1e-13, err_msg=adjoint)
        np.testing.assert_allclose(gx, g_x0, rtol=1e-13, err_msg=adjoint)


def test_interval_accelerometer_noise_has_the_per_step_statistics():
    """Per-step white noise (throttle_k sigma dt n_k added to the measured Δv of step k,
    carried to the interval's end by straight-line motion), sampled by brute force, has the
    covariance of the closed-form interval draw."""
    rng = np.random.default_rng(1)
    dt, steps, sigma = 1.0, 15, 1e-4
    throttle = np.zeros(steps)
    throttle[3:9] = 1.0
    throttle[11] = 0.4  # a fractional (relaxed or pulsed) step
    n = 200_000
    noise = rng.standard_normal((n, steps)) * throttle * sigma * dt  # one axis
    k = np.arange(steps)
    c = dt * (steps - k - 0.5)
    dv_bf, dr_bf = noise.sum(axis=1), noise @ c
    cov_bf = np.cov(np.stack([dr_bf, dv_bf]))

    moments = jnp.asarray(
        [np.sum(throttle**2), np.sum(throttle**2 * c), np.sum(throttle**2 * c**2)]
    )
    # the closed form is linear in its two normals per axis: read its covariance off the map
    e = np.eye(6)
    cols = [np.array(jnp.concatenate(accel_noise(sigma * dt, moments, jnp.asarray(u)))) for u in e]
    lin = np.stack(cols, axis=1)  # (dr, dv) = lin @ u
    cov_cf = (lin @ lin.T)[np.ix_([0, 3], [0, 3])]  # x axis: dr_x, dv_x
    np.testing.assert_allclose(cov_cf, cov_bf, rtol=0.02)
    # no firing: no noise
    zero = accel_noise(sigma * dt, jnp.zeros(3), jnp.ones(6))
    assert float(jnp.max(jnp.abs(jnp.concatenate(zero)))) == 0.0


@pytest.mark.parametrize("c_k", [7.5, 0.5, 14.5, 3.3])
def test_one_firing_step_gives_the_accelerometer_noise_a_finite_tangent(c_k):
    """The engine on in one control step of the interval: C - B^2/A is zero in exact
    arithmetic and rounds to either side of it. A relaxed law's throttle carries a tangent into
    the moments; the noise's tangent must stay finite (the square root's infinite slope at zero
    once made it NaN and poisoned a whole batch's gradient), and equal the one-step closed form:
    all the noise acts at the one step, dr = c_k dv."""
    u = jnp.asarray([0.3, -1.2, 0.7, 1.5, -0.4, 2.0])

    def noise(throttle):
        t2 = throttle**2
        return jnp.concatenate(accel_noise(1e-4, jnp.stack([t2, t2 * c_k, t2 * c_k**2]), u))

    value, tangent = jax.jvp(noise, (jnp.asarray(0.8),), (jnp.asarray(1.0),))
    assert np.all(np.isfinite(np.asarray(tangent))), tangent
    dv, ddv = 1e-4 * 0.8 * u[:3], 1e-4 * u[:3]
    np.testing.assert_allclose(value[3:], dv, rtol=1e-12)
    np.testing.assert_allclose(tangent[3:], ddv, rtol=1e-12)
    np.testing.assert_allclose(value[:3], c_k * dv, rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(tangent[:3], c_k * ddv, rtol=1e-6, atol=1e-15)


def test_tilt_direction_has_independent_angles_of_sigma_about_two_axes():
    rng = np.random.default_rng(2)
    u = np.array([0.3, -0.5, 0.8])
    u /= np.linalg.norm(u)
    sigma = 3e-3
    delta = rng.standard_normal((100_000, 3)) * sigma
    tilted = np.array(jax.vmap(lambda d: tilt_direction(jnp.asarray(u), d))(jnp.asarray(delta)))
    np.testing.assert_allclose(np.linalg.norm(tilted, axis=1), 1.0, rtol=1e-14)
    e1 = np.cross(u, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    a1, a2 = tilted @ e1, tilted @ e2
    assert abs(np.std(a1) / sigma - 1) < 0.02 and abs(np.std(a2) / sigma - 1) < 0.02
    assert abs(np.corrcoef(a1, a2)[0, 1]) < 0.02
    assert abs(np.mean(a1)) < 5 * sigma / np.sqrt(len(a1))


def test_closed_form_los_prediction_matches_jacfwd():
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    c = jnp.asarray(q)
    x = jnp.asarray([-4e6, 2e5, -1e5, 1.02e4, 3.0, -2.0])
    a = rng.standard_normal((6, 6))
    nav = NavEstimate(x, jnp.asarray(a @ a.T * 1e4))
    r_cov = 1e-10 * jnp.eye(2)
    ours, ref = predict_los(nav, c, r_cov), predict_measurement(nav, los_model(c), r_cov)
    for f in ("z", "jacobian", "s"):
        np.testing.assert_allclose(
            np.asarray(getattr(ours, f)), np.asarray(getattr(ref, f)), rtol=1e-10, atol=0
        )


def test_written_out_matmul_equals_numpy():
    rng = np.random.default_rng(4)
    for shape in ((6, 6, 2), (2, 3, 3), (3, 3, 3)):
        a, b = rng.standard_normal(shape[:2]), rng.standard_normal(shape[1:])
        np.testing.assert_allclose(
            np.asarray(matmul(jnp.asarray(a), jnp.asarray(b))), a @ b, rtol=1e-13
        )


def test_certain_filter_and_noiseless_measurement_update_stays_finite():
    """P = 0 and R = 0 give S = 0 (floored to 1e-200 I, whose determinant underflows): the
    written-out inverse must still give K = 0, as the LAPACK solve did."""
    from gnc_jax.navigation.ekf import ekf_update

    c = jnp.eye(3)
    nav = NavEstimate(jnp.asarray([-4e6, 2e5, -1e5, 1.02e4, 3.0, -2.0]), jnp.zeros((6, 6)))
    predicted = predict_los(nav, c, jnp.zeros((2, 2)))
    new, _ = ekf_update(nav, predicted.z + 1e-6, predicted)
    np.testing.assert_array_equal(np.asarray(new.x), np.asarray(nav.x))
    np.testing.assert_array_equal(np.asarray(new.p), 0.0)


def test_component_rk4_equals_the_vector_field_step():
    """The truth's RK4 by components (V3) is the same arithmetic as the array vector field:
    equal to the last bit, with thrust, mass flow, tide and point-mass gravity all on, for
    array and V3 states alike."""
    from gnc_jax._numerics import V3, as_array
    from gnc_jax.dynamics.impactor import ImpactorState, RelativeDynamics, rk4, vector_field
    from gnc_jax.integrate import rk4_step

    rng = np.random.default_rng(3)
    dyn = RelativeDynamics(jnp.asarray(4.5e3), jnp.asarray(2e-13), jnp.array([0.6, 0.8, 0.0]))
    for _ in range(5):
        y = ImpactorState(
            jnp.asarray(rng.normal(size=3) * 1e6), jnp.asarray(rng.normal(size=3) * 1e4), 372.0
        )
        thrust, flow = jnp.asarray(rng.normal(size=3) * 88.0), 0.04
        want = rk4_step(vector_field, 0.0, y, 1.3, (dyn, thrust, flow))
        got = rk4(dyn, y, thrust, flow, 1.3)
        got_v3 = rk4(dyn, y._replace(r=V3(*y.r), v=V3(*y.v)), thrust, flow, 1.3)
        assert isinstance(got_v3.r, V3)
        for g in (got, got_v3._replace(r=as_array(got_v3.r), v=as_array(got_v3.v))):
            np.testing.assert_array_equal(g.r, want.r)
            np.testing.assert_array_equal(g.v, want.v)
            np.testing.assert_array_equal(g.m, want.m)


def test_v3_arithmetic_matches_arrays():
    from gnc_jax._numerics import V3, as_array, as_v3

    a, b = jnp.array([1.5, -2.0, 3.25]), jnp.array([0.5, 4.0, -1.0])
    va = as_v3(a)
    for got, want in [
        (va + b, a + b),
        (b + va, b + a),
        (va - b, a - b),
        (b - va, b - a),
        (va + as_v3(b), a + b),
        (2.5 * va, 2.5 * a),
        (va * 2.5, a * 2.5),
        (va / 4.0, a / 4.0),
        (-va, -a),
        (va + 1.0, a + 1.0),
    ]:
        assert isinstance(got, V3)
        np.testing.assert_array_equal(as_array(got), want)
    assert as_v3(va) is va and as_array(a) is a


def test_vector_helpers_keep_the_callers_layout_and_its_bits():
    """cross3, sub3, axpy3, matvec3 and safe_unit return a V3 for a V3 operand and a (3,)
    array otherwise, with the same bits, under jit and vmap (an intercept carries its vectors
    by component on the strength of it); the layout trees convert back and forth."""
    from gnc_jax._numerics import (
        V3,
        as_array,
        as_arrays,
        as_components,
        axpy3,
        cross3,
        matvec3,
        safe_unit,
        sub3,
    )

    rng = np.random.default_rng(7)
    a, b = jnp.asarray(rng.normal(size=(16, 3))), jnp.asarray(rng.normal(size=(16, 3)))
    a = a.at[0].set(0.0)  # safe_unit's fallback
    m, s = jnp.asarray(rng.normal(size=(3, 3))), jnp.asarray(rng.normal(size=16))
    fallback = jnp.array([0.0, 0.0, 1.0])

    def helpers(a, b, s, by_component):
        a, b = (V3(*a), V3(*b)) if by_component else (a, b)
        out = (
            cross3(a, b),
            cross3(fallback, a),
            sub3(a, b),
            axpy3(s, a, b),
            matvec3(m, a),
            safe_unit(a, fallback),
        )
        assert all(isinstance(x, V3) == by_component for x in out)
        return tuple(as_array(x) for x in out)

    for want, got in zip(
        jax.jit(jax.vmap(lambda *x: helpers(*x, False)))(a, b, s),
        jax.jit(jax.vmap(lambda *x: helpers(*x, True)))(a, b, s),
    ):
        np.testing.assert_array_equal(got, want)
    tree = dict(r=a[1], p=(s[0], s[1]), q=jnp.zeros(2))
    comp = as_components(tree)
    assert isinstance(comp["r"], V3) and comp["q"].shape == (2,)
    np.testing.assert_array_equal(as_arrays(comp)["r"], a[1])


def test_computed_once_fences_with_an_integer_live_value():
    """``i == i`` of an integer folds to true in XLA, which would inline the branch and fence
    nothing: computed_once compares a float, so the conditional stays in the program."""
    fn = lambda x: jnp.sin(x) * 2.0  # noqa: E731
    f = jax.jit(jax.vmap(lambda x, i: computed_once(fn, i, x), in_axes=(0, None)))
    text = f.lower(jnp.ones(4), jnp.asarray(3, jnp.int32)).compile().as_text()
    assert "conditional" in text
