"""The skip-entry predictor's horizon: a prediction that flies on from the switch point to
the chute keeps the switch point's range error and judges the chute's crossrange."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.dynamics.entry import EntryState
from gnc_jax.guidance.entry.base import EntryModel
from gnc_jax.guidance.entry.predictor import predict, second_entry_cos
from gnc_jax.guidance.entry.tracking import track
from gnc_jax.systems.capsule.simulation import guidance_context


@pytest.fixture(scope="module")
def cycles():
    """The law, its context and the corrector cycles of a flight after the pull-up starts
    (every third), as batched predictor inputs."""
    sim, law = gj.build(gj.load_scenario("lunar-skip-entry"))
    ctx = guidance_context(sim)
    _, tr = gj.simulate_one(gj.load_scenario("lunar-skip-entry"), index=0, seed=0)
    i = np.flatnonzero(tr.corrector_evals > 0)[::3]
    c = ctx.model
    model = jax.vmap(lambda d, l: EntryModel(c.vehicle, c.earth, c.atmosphere, d, l))(
        jnp.asarray(tr.drag_ratio[i]), jnp.asarray(tr.lift_ratio[i])
    )
    y = EntryState(jnp.asarray(tr.r_m[i]), jnp.asarray(tr.v_mps[i]))
    inputs = (y, jnp.asarray(tr.t_s[i]), jnp.asarray(tr.pulled_up[i]), tr.sigma_0_rad[i], model)
    return law, ctx, inputs


@jax.jit
def _predict(law, target_fixed, y, t, up, sigma, model):
    def one(y, t, up, s0, m):
        p = predict(law, y, t, up, s0, m, target_fixed)
        return p.miss_m, p.crossrange_m, p.kind, p.steps

    return jax.vmap(one)(y, t, up, sigma, model)


def predictions(law, ctx, inputs):
    """The predictions of ``law`` at the cycles ``inputs``: one program per law setting and
    batch shape, shared by the tests (the law is an argument of the program)."""
    y, t, up, sigma, model = inputs
    out = _predict(law, ctx.target_fixed, y, t, up, jnp.asarray(sigma), model)
    return [np.asarray(x) for x in out]


def test_flying_on_to_the_chute_keeps_the_switch_points_range_error(cycles):
    """``chute_crossrange``, for the cycles after the pull-up: the range errors (to rounding:
    another program) and kinds of ``switch``, the crossrange of the prediction flown on to
    the chute (``chute``), and that crossrange differs from the switch point's by the drift
    under the second entry (tens of km at the paper's 2,000 km second entry), at about twice
    the steps. Before the pull-up every horizon is ``switch``, steps included."""
    law, ctx, inputs = cycles
    law = dataclasses.replace(law, predictor_horizon="switch")
    m_s, x_s, k_s, n_s = predictions(law, ctx, inputs)
    on = dataclasses.replace(law, predictor_horizon="chute_crossrange")
    m_c, x_c, k_c, n_c = predictions(on, ctx, inputs)
    m_f, x_f, k_f, n_f = predictions(
        dataclasses.replace(law, predictor_horizon="chute"), ctx, inputs
    )
    after = np.asarray(inputs[2])
    assert 3 <= after.sum() <= len(after) - 3
    np.testing.assert_array_equal(k_s, 0)
    np.testing.assert_array_equal(k_c, 0)
    np.testing.assert_array_equal(k_f[after], 1)  # the chute reached
    np.testing.assert_allclose(m_c, m_s, rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(x_c[after], x_f[after], rtol=1e-12, atol=1e-6)
    np.testing.assert_array_equal(n_c, n_f)
    drift = (x_c - x_s)[after] / 1e3
    assert 5.0 < np.median(np.abs(drift)) < 60.0
    assert 1.4 * n_s[after].sum() < n_c[after].sum() < 2.5 * n_s[after].sum()
    before = ~after
    for m, x, k, n in ((m_c, x_c, k_c, n_c), (m_f, x_f, k_f, n_f)):
        np.testing.assert_array_equal(k[before], 0)
        np.testing.assert_array_equal(n[before], n_s[before])
        np.testing.assert_allclose(m[before], m_s[before], rtol=1e-12, atol=1e-6)
        np.testing.assert_allclose(x[before], x_s[before], rtol=1e-12, atol=1e-6)


def test_a_prediction_without_a_switch_point_is_the_same_whatever_the_horizon(cycles):
    """Banks 9 deg steeper than the flown ones: the early cycles' predictions land without a
    skip (kind 1), the later ones pass the switch point. The first are the same to rounding
    under every horizon, range error and crossrange."""
    law, ctx, (y, t, up, sigma, model) = cycles
    law = dataclasses.replace(law, predictor_horizon="switch")
    steep = (y, t, up, sigma + np.radians(9.0), model)
    m_s, x_s, k_s, _ = predictions(law, ctx, steep)
    assert 0 < np.sum(k_s == 1) < len(k_s)
    landed = k_s == 1
    for horizon in ("chute_crossrange", "chute"):
        m, x, k, _ = predictions(dataclasses.replace(law, predictor_horizon=horizon), ctx, steep)
        np.testing.assert_array_equal(k[landed], 1)
        np.testing.assert_allclose(m[landed], m_s[landed], rtol=1e-12, atol=1e-6)
        np.testing.assert_allclose(x[landed], x_s[landed], rtol=1e-12, atol=1e-6)


def test_the_chute_crossrange_converges_with_the_predictor_step(cycles):
    """The crossrange at the chute of the last cycles, flown in steps of 8 s and 4 s against
    1 s steps: within 0.5 km at 4 s, and closer at 4 s than at 8 s (measured 0.2 and 1.2 km
    at most): the flight on and the chute's location inside the last step are right, not
    only consistent."""
    law, ctx, inputs = cycles
    on = dataclasses.replace(law, predictor_horizon="chute")
    late = jax.tree_util.tree_map(lambda x: x[-6:], inputs)

    def chute_crossrange(dt, bank="midpoint"):
        steps = dataclasses.replace(
            on,
            predictor_bank=bank,
            predictor_dt_s=dt,
            predictor_coast_dt_s=dt,
            predictor_max_steps=4000,
        )
        _, x, k, _ = predictions(steps, ctx, late)
        np.testing.assert_array_equal(k, 1)
        return x

    fine = chute_crossrange(1.0, bank="step")
    err_8, err_4 = (np.max(np.abs(chute_crossrange(dt) - fine)) for dt in (8.0, 4.0))
    assert err_4 < 0.5e3
    assert err_4 < err_8


def test_a_tracked_second_entry_flies_the_tracking_command_without_feedback(cycles):
    """``second_entry_bank = "tracked"``: the cosine a prediction flies in a second entry is
    the one the law's tracking (eq. 6) commands on the reference with no deviation, for a
    model whose L/D is off the reference's either way; with the model's L/D on it, the
    reference's own cosine."""
    law, ctx, _ = cycles
    law = dataclasses.replace(law, second_entry_bank="tracked")
    ref = law.reference
    speeds = np.linspace(float(ref.velocity_mps[-1]), float(ref.velocity_mps[0]), 7)
    c = ctx.model
    for drag_ratio, lift_ratio in ((0.70, 0.78), (1.10, 0.95), (0.9, 0.9)):
        model = EntryModel(c.vehicle, c.earth, c.atmosphere, drag_ratio, lift_ratio)
        for v in speeds:
            _, s, hdot, ngx, sdot = ref.lookup(v)
            bank = track(law, v, ngx, hdot, s, sdot, lift_ratio / drag_ratio, 0.0)
            np.testing.assert_allclose(
                second_entry_cos(law, v, model), np.cos(bank), rtol=0, atol=1e-12
            )
            if drag_ratio == lift_ratio:
                np.testing.assert_allclose(
                    second_entry_cos(law, v, model), np.cos(ref.bank_at(v)), rtol=0, atol=1e-12
                )


def test_a_tracked_second_entry_lands_as_its_ld_says(cycles):
    """Predictions flown on to the chute (``predictor_horizon = "chute"``, the cycles after
    the pull-up): with the cycles' measured ratios (an L/D 6 % under the model's), the
    tracked second entry flies more vertical lift than the reference's bank and lands more
    than a kilometre longer; with the lift ratio set to the drag ratio, the two are the same
    to rounding."""
    law, ctx, inputs = cycles
    after = np.flatnonzero(np.asarray(inputs[2]))
    y, t, up, sigma, model = jax.tree_util.tree_map(lambda x: x[after], inputs)
    ld = np.asarray(model.lift_ratio / model.drag_ratio)
    assert np.all(ld < 0.97)
    on = dataclasses.replace(law, predictor_horizon="chute", second_entry_bank="reference")
    tracked = dataclasses.replace(on, second_entry_bank="tracked")
    m_ref, _, k_ref, _ = predictions(on, ctx, (y, t, up, sigma, model))
    m_tr, _, k_tr, _ = predictions(tracked, ctx, (y, t, up, sigma, model))
    np.testing.assert_array_equal(k_ref, 1)
    np.testing.assert_array_equal(k_tr, 1)
    assert np.all(m_tr > m_ref + 1.0e3)
    same = dataclasses.replace(model, lift_ratio=model.drag_ratio)
    m_ref, x_ref, _, _ = predictions(on, ctx, (y, t, up, sigma, same))
    m_tr, x_tr, _, _ = predictions(tracked, ctx, (y, t, up, sigma, same))
    np.testing.assert_allclose(m_tr, m_ref, rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(x_tr, x_ref, rtol=1e-12, atol=1e-6)
