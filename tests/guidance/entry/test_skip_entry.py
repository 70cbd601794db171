"""The capsule law as a member of the entry-guidance family: registry, ratio filter, schedule."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax._numerics import for_platform, loop_shape, using_lanes, using_loop_shape
from gnc_jax.dynamics.entry import EntryConditions, entry_state_from_conditions
from gnc_jax.guidance.base import family_of
from gnc_jax.guidance.entry.base import (
    AbstractEntryGuidance,
    EntryNav,
    FlightVariables,
    drag_and_lift,
    flight_variables,
)
from gnc_jax.guidance.entry.corrector import correct
from gnc_jax.guidance.entry.phases import (
    apogee_gate,
    bank_sign,
    phase_events,
    switch_by_speed,
    switch_threshold_m,
)
from gnc_jax.guidance.entry.predictor import FENCE_MIN_LANES, filter_ratios, predict
from gnc_jax.guidance.entry.skip_entry import SkipEntryGuidance
from gnc_jax.systems.capsule.simulation import guidance_context


@pytest.fixture(scope="module")
def law_and_ctx():
    sim, law = gj.build(gj.load_scenario("lunar-skip-entry"))
    return sim, law, guidance_context(sim)


@pytest.fixture(scope="module")
def flight():
    """The trace of a flight of the packaged scenario (run 0): its corrector cycles are the
    states the predictor and corrector tests start from."""
    return gj.simulate_one(gj.load_scenario("lunar-skip-entry"), index=0, seed=0)[1]


def state_at(altitude_m, ctx, fpa_deg=-5.0):
    return entry_state_from_conditions(
        EntryConditions(altitude_m, 10.0e3, np.radians(fpa_deg), 0.6, 1.0, 0.2), ctx.model.earth
    )


def test_registered_in_the_entry_family():
    assert family_of(SkipEntryGuidance) is AbstractEntryGuidance
    assert AbstractEntryGuidance.laws["skip_entry"] is SkipEntryGuidance
    assert SkipEntryGuidance.law_name == "skip_entry"


def test_accelerometer_split_matches_the_aerodynamic_coefficients(law_and_ctx):
    # Bank 0: drag along -v_rel and lift normal to it, in the ratio C_L / C_D of the vehicle.
    _, _, ctx = law_and_ctx
    m = ctx.model
    drag, lift = drag_and_lift(state_at(60e3, ctx), m.vehicle, m.earth, m.atmosphere)
    assert float(drag) > 0.0
    np.testing.assert_allclose(float(lift / drag), float(m.vehicle.c_l / m.vehicle.c_d), rtol=1e-12)


def test_ratio_filter_is_first_order_towards_the_measured_ratios(law_and_ctx):
    """n filter steps on constant measurements: ratio_n = r + (1 - k)^n (1 - r)."""
    _, law, ctx = law_and_ctx
    y = state_at(60e3, ctx)
    m = ctx.model
    drag, lift = drag_and_lift(y, m.vehicle, m.earth, m.atmosphere)
    nav = EntryNav(y, 1.3 * drag, 0.8 * lift)
    state = law.init(nav, ctx)
    ng = jnp.sqrt(nav.drag_mps2**2 + nav.lift_mps2**2) / 9.80665
    assert float(ng) > 0.05
    n = 7
    for _ in range(n):
        dr, lr = filter_ratios(law, state, nav, ng, ctx)
        state = state._replace(drag_ratio=dr, lift_ratio=lr)
    decay = (1.0 - float(ctx.ratio_filter_gain)) ** n
    np.testing.assert_allclose(float(state.drag_ratio), 1.3 + decay * (1.0 - 1.3), rtol=1e-12)
    np.testing.assert_allclose(float(state.lift_ratio), 0.8 + decay * (1.0 - 0.8), rtol=1e-12)
    # Below 0.05 g the ratios are not updated.
    low = nav._replace(drag_mps2=1e-3 * drag, lift_mps2=1e-3 * lift)
    assert filter_ratios(law, state, low, jnp.asarray(0.01), ctx) == (
        state.drag_ratio,
        state.lift_ratio,
    )


def test_guidance_holds_then_runs_the_corrector_every_pc_every_steps(law_and_ctx):
    """Hold phase below ng0; once guiding (phase 1) the corrector runs on steps 0, p, 2p, ..."""
    _, law, ctx = law_and_ctx
    m = ctx.model
    step = jax.jit(lambda s, nav, t, ctx: law.step(s, nav, t, ctx))

    def nav_at(y):
        return EntryNav(y, *drag_and_lift(y, m.vehicle, m.earth, m.atmosphere))

    def init(nav):  # typed as step returns it: a weakly typed leaf would compile step again
        return jax.tree_util.tree_map(lambda x: jnp.asarray(x, x.dtype), law.init(nav, ctx))

    high = nav_at(state_at(119e3, ctx))  # almost no load: hold
    state = init(high)
    command, held = step(state, high, 0.0, ctx)
    # the hold flies the designed first-entry bank (hold_bank = "designed"), or the scenario's
    assert int(held.phase) == 0 and float(command) == float(law.reference.first_entry_bank_rad)
    scenario_hold = dataclasses.replace(law, hold_bank="scenario")
    command, _ = scenario_hold.step(scenario_hold.init(high, ctx), high, 0.0, ctx)
    assert float(command) == float(ctx.hold_bank_rad) != float(law.reference.first_entry_bank_rad)
    assert int(held.log.pc_cycles) == 0

    y = state_at(65e3, ctx, fpa_deg=-6.0)
    nav = nav_at(y)
    n_steps = 2 * ctx.pc_every + 1
    cycles = []
    state = init(nav)
    for k in range(n_steps):
        _, state = step(state, nav, 10.0 + k, ctx)
        assert int(state.phase) == 1
        cycles.append(int(state.log.pc_cycles))
    expected = [k // ctx.pc_every + 1 for k in range(n_steps)]
    assert cycles == expected
    assert int(state.log.predictions) >= len(set(expected))
    assert float(state.log.t_guidance_s) == 10.0


def test_guidance_stops_below_the_chute_altitude(law_and_ctx):
    _, law, ctx = law_and_ctx
    m = ctx.model
    y = state_at(float(law.chute_altitude_m) - 10.0, ctx, fpa_deg=-60.0)
    assert float(flight_variables(y, m.earth).altitude_m) < float(law.chute_altitude_m)
    nav = EntryNav(y, *drag_and_lift(y, m.vehicle, m.earth, m.atmosphere))
    state = law.init(nav, ctx)
    _, new = law.step(state, nav, 0.0, ctx)
    assert int(new.phase) == 0  # a load far above ng0 does not start guidance
    assert int(new.log.pc_cycles) == 0 and int(new.log.reversals) == 0
    assert not bool(new.log.skipped_out)


def test_reference_lookup_interpolates_as_jnp_interp(law_and_ctx):
    """The reference tables are looked up by arithmetic on their uniform speed grid; the
    reference is numpy-style linear interpolation (jnp.interp), clamped at both ends."""
    _, law, _ = law_and_ctx
    ref = law.reference
    v = np.asarray(ref.velocity_mps)
    np.testing.assert_allclose(np.diff(v), np.diff(v)[0], rtol=1e-9)  # uniform grid
    speeds = np.concatenate(
        [np.random.default_rng(1).uniform(v[-1] - 500.0, v[0] + 500.0, 500), v, [v[0], v[-1]]]
    )
    got = jax.vmap(ref.lookup)(jnp.asarray(speeds))
    tables = (ref.bank_rad, ref.range_to_go_m, ref.hdot_mps, ref.drag_load_g, ref.range_rate_mps)
    for value, table in zip(got, tables):
        expected = np.interp(speeds, v[::-1], np.asarray(table)[::-1])
        scale = np.max(np.abs(np.asarray(table)))
        np.testing.assert_allclose(value, expected, rtol=1e-12, atol=1e-12 * scale)


def test_predictor_coast_step_costs_less_accuracy_than_the_corrector_tolerance(law_and_ctx, flight):
    """The predictor's coast steps (32 s below 0.02 g: the Kepler arc) against its 16 s steps
    throughout, at the states and the solutions of the corrector cycles of a flight: the
    predicted range errors differ by less than the corrector's tolerance, with about 30 %
    fewer integration steps to the switch point (``predictor_horizon = "switch"``: the flight
    on to the chute has no coast)."""
    import dataclasses

    from gnc_jax.dynamics.entry import EntryState
    from gnc_jax.guidance.entry.base import EntryModel

    sim, law, ctx = law_and_ctx
    law = dataclasses.replace(law, predictor_horizon="switch")
    assert law.predictor_coast_dt_s > law.predictor_dt_s
    fine = dataclasses.replace(law, predictor_coast_dt_s=law.predictor_dt_s)
    tr = flight
    cycles = np.flatnonzero(tr.corrector_evals > 0)[::6]
    assert len(cycles) >= 6

    @jax.jit
    @jax.vmap
    def predictions(i):
        def one(l):
            c = ctx.model
            dr, lr = jnp.asarray(tr.drag_ratio)[i], jnp.asarray(tr.lift_ratio)[i]
            m = EntryModel(c.vehicle, c.earth, c.atmosphere, dr, lr)
            y = EntryState(jnp.asarray(tr.r_m)[i], jnp.asarray(tr.v_mps)[i])
            s0 = jnp.asarray(tr.sigma_0_rad)[i]
            t, up = jnp.asarray(tr.t_s)[i], jnp.asarray(tr.pulled_up)[i]
            p = predict(l, y, t, up, s0, m, ctx.target_fixed)
            return p.miss_m, p.kind, p.steps

        return one(law), one(fine)

    coarse, reference = predictions(jnp.asarray(cycles))
    np.testing.assert_array_equal(coarse[1], 0)  # every prediction ends at the switch point
    np.testing.assert_array_equal(reference[1], 0)
    assert float(jnp.max(jnp.abs(coarse[0] - reference[0]))) < float(law.range_tolerance_m)
    assert int(jnp.sum(coarse[2])) < 0.75 * int(jnp.sum(reference[2]))


def test_levelling_off_at_the_dip_is_not_a_pull_up_nor_a_second_entry(law_and_ctx):
    """Phase logic (law; the predictor uses the same rule): a vehicle that levels off at the
    bottom of its first dip (climbs a few metres while a reversal rolls, then sinks again at
    3 g) stays in the first entry; one that rose ``pull_up_rise_m`` above the dip has pulled up,
    and its descent at a load above the Kepler threshold starts the second entry (phase 3)."""
    _, law, ctx = law_and_ctx
    m = ctx.model
    y = state_at(61.6e3, ctx)
    nav = EntryNav(y, *drag_and_lift(y, m.vehicle, m.earth, m.atmosphere))
    state = law.init(nav, ctx)._replace(phase=jnp.asarray(1))
    live = jnp.asarray(True)

    def after(altitudes, hdots, ng):
        s = state
        for h, hd in zip(altitudes, hdots):
            fv = FlightVariables(jnp.asarray(9.5e3), jnp.asarray(0.0), h, jnp.asarray(hd))
            phase, pulled, dip, _ = phase_events(law, s, fv, jnp.asarray(ng), live)
            s = s._replace(phase=phase, pulled_up=pulled, dip_altitude_m=dip)
        return s

    dip = [61_600.0, 61_583.0, 61_586.0, 61_588.0, 61_587.0, 61_575.0]
    level = after(dip, [-5.0, -1.0, 2.0, 2.0, -2.5, -9.0], 3.1)
    assert int(level.phase) == 1 and not bool(level.pulled_up)
    assert float(level.dip_altitude_m) == 61_575.0
    rise = float(law.pull_up_rise_m)
    climbed = after(dip[:2] + [61_583.0 + rise + 10.0], [-5.0, -1.0, 40.0], 3.0)
    assert bool(climbed.pulled_up) and int(climbed.phase) == 1
    state_climbed = climbed
    fv = FlightVariables(jnp.asarray(9.0e3), jnp.asarray(0.0), 62_000.0, jnp.asarray(-30.0))
    phase, *_ = phase_events(law, state_climbed, fv, jnp.asarray(1.5), live)
    assert int(phase) == 3


def _corrector_cycles(law_and_ctx, flight, every=4):
    """States of the corrector cycles of a flight (every ``every``-th), as batched inputs
    of the predictor: (y, t, pulled up, sigma_0 of the cycle, model)."""
    from gnc_jax.dynamics.entry import EntryState
    from gnc_jax.guidance.entry.base import EntryModel

    _, _, ctx = law_and_ctx
    tr = flight
    i = np.flatnonzero(tr.corrector_evals > 0)[::every]
    c = ctx.model
    model = jax.vmap(lambda d, l: EntryModel(c.vehicle, c.earth, c.atmosphere, d, l))(
        jnp.asarray(tr.drag_ratio[i]), jnp.asarray(tr.lift_ratio[i])
    )
    y = EntryState(jnp.asarray(tr.r_m[i]), jnp.asarray(tr.v_mps[i]))
    return y, jnp.asarray(tr.t_s[i]), jnp.asarray(tr.pulled_up[i]), tr.sigma_0_rad[i], model


def test_corrector_rounds_equal_the_slot_wise_corrector(law_and_ctx, flight):
    """The corrector advances every run of a batch to its next prediction as soon as its own
    ends (rounds of ROUND_STEPS predictor steps): at the cycles of a flight, batched (runs of
    different prediction counts and lengths side by side), it returns what the corrector whose
    k-th prediction is slot k of a fixed scan of predictions (``bounded_regula_falsi_with_aux``
    of ``predict``) returns run by run: the same solution, predictions, steps and crossrange.
    The starts are offset from the flown solutions so that every stage of the solve runs."""
    from gnc_jax.root_finding import bounded_regula_falsi_with_aux

    _, law, ctx = law_and_ctx
    y, t, up, sigma, model = _corrector_cycles(law_and_ctx, flight)
    offsets = np.resize(np.radians([0.0, 2.0, -7.0, 12.0, -0.3]), len(sigma))
    start = jnp.asarray(sigma + offsets)

    def rounds(y, t, up, s0, m):
        return correct(law, y, t, up, s0, m, ctx.target_fixed, jnp.asarray(True))

    def slots(y, t, up, s0, m):
        def miss(s, active):
            p = predict(law, y, t, up, s, m, ctx.target_fixed, active)
            return p.miss_m, p.crossrange_m, p.steps.astype(float)

        return bounded_regula_falsi_with_aux(
            miss,
            s0,
            law.bracket_step_rad,
            law.bank_min_rad,
            law.bank_max_rad,
            law.range_tolerance_m,
            law.n_bracket,
            law.n_iter,
        )

    batched = jax.jit(jax.vmap(rounds))(y, t, up, start, model)
    per_run = jax.jit(slots)
    assert len(set(np.asarray(batched.n_evals_early_exit).tolist())) >= 3
    for i in range(len(sigma)):
        one = per_run(*jax.tree_util.tree_map(lambda a, i=i: a[i], (y, t, up, start, model)))
        for name in ("n_evals_early_exit", "status", "cost"):
            np.testing.assert_array_equal(getattr(batched, name)[i], getattr(one, name))
        for name in ("x", "f_x", "aux", "slope"):
            np.testing.assert_allclose(getattr(batched, name)[i], getattr(one, name), rtol=1e-9)


def corrector_solves(ctx, law, y, t, up, s0, model, loop_kind="lax"):
    """The corrector's solves of a batch of cycles (enabled), the law an argument as in a
    study."""

    def one(y, t, up, s0, m):
        return correct(
            law, y, t, up, s0, m, ctx.target_fixed, jnp.asarray(True), loop_kind=loop_kind
        )

    return jax.vmap(one)(y, t, up, s0, model)


def assert_same_solve(a, b):
    """The same solve: statuses, counts and step costs identical, floats to the slot-wise test's
    1e-9 (two programs of the same arithmetic differ by XLA's fusion only: 2e-16 relative in a
    bank, 3e-12 in a secant slope, a difference quotient; a wrong step or a missed round moves a
    solution by far more). The range error ``f_x`` is the difference of a predicted and a
    target range of about 1e7 m, whose last bit is 2e-9 m: it is compared to 1e-6 m (the
    loops measured up to 1.5e-7 m apart at the cycles of a flight; a wrong step moves it by
    metres)."""
    for name in a._fields:
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        if np.issubdtype(y.dtype, np.floating):
            atol = 1e-6 if name == "f_x" else 1e-9
            np.testing.assert_allclose(x, y, rtol=1e-9, atol=atol, err_msg=name)
        else:
            np.testing.assert_array_equal(x, y, err_msg=name)


def test_corrector_loop_kinds_and_layouts_equal_the_while_loop(law_and_ctx, flight):
    """The corrector's rounds as a masked scan of their bound (``loop_kind = "fixed"``), in an
    accelerator's layout (``LoopShape.early_exit`` false: a round's predictor steps a masked
    scan of ``ROUND_STEPS`` unrolled whole, instead of a ``while_loop`` that stops when every
    run's prediction has ended) return what the ``lax`` ``while_loop`` returns in the CPU's
    layout at the cycles of a flight, batched (:func:`assert_same_solve`). Reverse mode's
    (``"checkpointed"``, the ``lax`` solve): the next test. The capsule's closed loop in the
    accelerator's layout otherwise: tests/test_loop_shape.py."""
    _, law, ctx = law_and_ctx
    y, t, up, sigma, model = _corrector_cycles(law_and_ctx, flight, every=6)
    start = jnp.asarray(sigma + np.resize(np.radians([0.0, 2.0, -7.0]), len(sigma)))
    runs = (law, y, t, up, start, model)
    solve = lambda kind: lambda *a: corrector_solves(ctx, *a, loop_kind=kind)  # noqa: E731
    lax_ = jax.jit(solve("lax"))(*runs)  # the unfenced program of the next test
    fixed = jax.jit(solve("fixed"))(*runs)  # no loop predicate
    accelerator = for_platform("gpu", gj.get_system("capsule"))
    assert not accelerator.early_exit and loop_shape().early_exit
    with using_loop_shape(accelerator):  # a new function: JAX caches a trace, not the layout
        unrolled = jax.jit(solve("lax"))(*runs)
    assert len(set(np.asarray(lax_.n_evals_early_exit).tolist())) >= 2
    assert_same_solve(fixed, lax_)
    assert_same_solve(unrolled, lax_)


def test_the_predictor_step_is_fenced_for_large_batches_only(law_and_ctx, flight):
    """A study's chunk of at least FENCE_MIN_LANES runs per device computes the predictor
    step's stages, phase logic and next bank once into memory (conditionals in the compiled
    corrector, the law an argument as in a study); a smaller one leaves them to fusion. Both
    solve alike at the cycles of a flight (:func:`assert_same_solve`)."""
    _, law, ctx = law_and_ctx
    y, t, up, sigma, model = _corrector_cycles(law_and_ctx, flight, every=6)
    start = jnp.asarray(sigma + np.resize(np.radians([0.0, 2.0, -7.0]), len(sigma)))

    conds, solves = [], []
    for lanes in (FENCE_MIN_LANES - 1, FENCE_MIN_LANES):
        with using_lanes(lanes):  # a new function each: JAX caches a trace, not the lanes
            fn = jax.jit(lambda *a: corrector_solves(ctx, *a))
            compiled = fn.lower(law, y, t, up, start, model).compile()
        conds.append(compiled.as_text().count(" conditional("))
        solves.append(compiled(law, y, t, up, start, model))
    assert conds[1] >= conds[0] + 3  # three RK4 stages, the phases and the bank
    assert_same_solve(solves[1], solves[0])


def test_implicit_corrector_derivative_is_the_derivative_of_the_root(law_and_ctx, flight):
    """Reverse mode through the corrector (``loop_kind = "checkpointed"``, what the capsule flies
    in reverse mode) returns the ``lax`` solve's values, and the derivative of its
    solution and predicted crossrange with respect to the speed at the cycle is that of the
    root: central differences of solves converged to 0.1 mm at the cycles of a flight,
    batched. An idle run passes the derivative of its previous solution (1) and nothing else.
    (The default 5 km tolerance leaves most solutions at their warm start, where the solve's
    own derivative is zero: the root's is what reverse mode follows.)"""
    _, law, ctx = law_and_ctx
    y, t, up, sigma, model = _corrector_cycles(law_and_ctx, flight, every=6)
    tight = eqx.tree_at(lambda l: l.range_tolerance_m, law, jnp.asarray(1e-4))
    tight = dataclasses.replace(tight, n_iter=40)
    enabled = jnp.asarray(np.arange(len(t)) % 4 != 3)

    def solve(kind, scale, s0):
        def one(y, t, up, s0, m, on):
            y = y._replace(v=y.v * scale)
            return correct(tight, y, t, up, s0, m, ctx.target_fixed, on, loop_kind=kind)

        return jax.vmap(one)(y, t, up, s0, model, enabled)

    weights = jnp.linspace(1.0, 2.0, len(t))

    def summary(res):  # an idle run's crossrange is none the law uses
        return jnp.sum(weights * res.x) + 1e-6 * jnp.sum(jnp.where(enabled, res.aux, 0.0))

    def implicit(scale, s0):
        res = solve("checkpointed", scale, s0)
        return summary(res), res

    s0 = jnp.asarray(sigma)
    (_, res), (d_scale, d_s0) = jax.jit(jax.value_and_grad(implicit, argnums=(0, 1), has_aux=True))(
        1.0, s0
    )
    solved = jax.jit(lambda scale: solve("lax", scale, s0))
    lax_ = solved(1.0)
    assert_same_solve(res, lax_)
    assert np.all(np.asarray(lax_.status)[np.asarray(enabled)] == 0)
    assert np.all(np.abs(np.asarray(lax_.f_x))[np.asarray(enabled)] < 1e-4)
    h = 1e-7
    cd = (float(summary(solved(1.0 + h))) - float(summary(solved(1.0 - h)))) / (2 * h)
    assert abs(cd) > 10.0  # the roots move with the speed
    np.testing.assert_allclose(float(d_scale), cd, rtol=1e-5)
    np.testing.assert_array_equal(np.asarray(d_s0), np.where(enabled, 0.0, weights))


def test_midpoint_bank_at_16_s_predicts_closer_to_fine_steps_than_the_held_bank_at_8_s(
    law_and_ctx,
    flight,
):
    """The predictor's default, the bank at the extrapolated mid-step speed with 16 s steps,
    predicts the range errors of the cycles of a flight closer to those of 0.5 s steps than
    the bank held over 8 s steps (a first-order error) does, with fewer steps."""
    import dataclasses

    _, law, ctx = law_and_ctx
    assert law.predictor_bank == "midpoint" and law.predictor_dt_s == 16.0
    y, t, up, sigma, model = _corrector_cycles(law_and_ctx, flight)

    def miss(variant):
        def one(y, t, up, s0, m):
            p = predict(variant, y, t, up, s0, m, ctx.target_fixed)
            return p.miss_m, p.kind, p.steps

        return jax.jit(jax.vmap(one))(y, t, up, jnp.asarray(sigma), model)

    fine = dataclasses.replace(
        law,
        predictor_bank="step",
        predictor_dt_s=0.5,
        predictor_coast_dt_s=0.5,
        predictor_max_steps=5000,
    )
    held = dataclasses.replace(law, predictor_bank="step", predictor_dt_s=8.0)
    (m_f, k_f, _), (m_m, k_m, s_m), (m_h, k_h, s_h) = miss(fine), miss(law), miss(held)
    np.testing.assert_array_equal(k_m, k_f)
    np.testing.assert_array_equal(k_h, k_f)
    rms = lambda e: float(jnp.sqrt(jnp.mean(e**2)))  # noqa: E731
    assert rms(m_m - m_f) < 0.8 * rms(m_h - m_f)
    assert int(jnp.sum(s_m)) < 0.75 * int(jnp.sum(s_h))


def test_switch_point_is_smooth_in_the_bank(law_and_ctx, flight):
    """The range error along sigma_0 near a solution at the peak load (where it is steepest,
    about 1000 km per degree) departs from a cubic by well under the corrector's 5 km
    tolerance: the switch point is located inside the last 16 s step on the load's log-linear
    crossing in altitude and the Hermite interpolant of the trajectory. (With the load
    interpolated linearly in time the wiggles reach the tolerance, and the corrector fails to
    converge in about 1 cycle of 3000.)"""
    _, law, ctx = law_and_ctx
    y, t, up, sigma, model = _corrector_cycles(law_and_ctx, flight, every=1)
    load = jax.vmap(lambda y, m: m.load_g(y))(y, model)
    i = int(jnp.argmax(load))
    pick = lambda a: a[i]  # noqa: E731
    y, t, up, s0, m = jax.tree_util.tree_map(pick, (y, t, up, jnp.asarray(sigma), model))
    d = jnp.radians(jnp.linspace(-0.2, 0.2, 201))
    f = jax.jit(jax.vmap(lambda s: predict(law, y, t, up, s0 + s, m, ctx.target_fixed).miss_m))(d)
    fit = np.polyval(np.polyfit(np.asarray(d), np.asarray(f), 3), np.asarray(d))
    assert float(np.ptp(np.asarray(f))) > 100e3  # steep
    assert float(np.max(np.abs(np.asarray(f) - fit))) < 1.5e3


def test_a_fast_crest_is_not_an_apogee_switch(law_and_ctx):
    """With ``apogee_switch = "apogee"``, a reference without a Kepler phase (its switch point
    is the skip's apogee, drag load above the threshold there) starts tracking at a pulled-up
    descent only within
    ``apogee_switch_margin_mps`` of its switch speed; a crest 500 m/s faster (a ripple deep in
    the atmosphere) stays in the first entry, in the law and in its predictor. A reference
    ending a Kepler arc (the packaged one) is not gated."""
    _, law, ctx = law_and_ctx
    ref = law.reference
    assert not bool(ref.switch_at_apogee(law.kepler_load_g))
    apogee = eqx.tree_at(lambda g: g.reference.drag_load_g, law, ref.drag_load_g.at[0].set(0.6))
    apogee = dataclasses.replace(apogee, apogee_switch="apogee")
    assert bool(apogee.reference.switch_at_apogee(apogee.kepler_load_g))
    m = ctx.model
    y = state_at(61.6e3, ctx)
    nav = EntryNav(y, *drag_and_lift(y, m.vehicle, m.earth, m.atmosphere))
    live = jnp.asarray(True)
    v_sw = float(ref.switch_velocity_mps)
    margin = float(law.apogee_switch_margin_mps)
    for g, dv, want in [
        (apogee, margin + 500.0, 1),
        (apogee, margin - 100.0, 3),
        (law, margin + 500.0, 3),
    ]:
        state = g.init(nav, ctx)._replace(
            phase=jnp.asarray(1), pulled_up=jnp.asarray(True), dip_altitude_m=jnp.asarray(60e3)
        )
        fv = FlightVariables(jnp.asarray(v_sw + dv), jnp.asarray(0.0), 62e3, jnp.asarray(-5.0))
        phase, *_ = phase_events(g, state, fv, jnp.asarray(1.5), live)
        assert int(phase) == want
        assert bool(apogee_gate(g, jnp.asarray(v_sw + dv))) == (want == 3)


def test_first_entry_reversal_threshold_narrows_towards_the_kepler_load(law_and_ctx):
    """The first entry reverses on the crossrange predicted at the switch point beyond
    ``switch_crossrange_m``; after the pull-up the threshold narrows linearly with the load,
    from that at ``switch_narrow_load_g`` to ``switch_crossrange_final_m`` at the Kepler load
    (hand-computed values), so a run does not coast into the Kepler arc with a predicted
    crossrange just under the wide threshold."""
    _, law, ctx = law_and_ctx
    wide, final = float(law.switch_crossrange_m), float(law.switch_crossrange_final_m)
    lo, hi = float(law.kepler_load_g), float(law.switch_narrow_load_g)
    f = lambda pulled, ng: switch_threshold_m(law, pulled, ng)
    t, fa = jnp.asarray(True), jnp.asarray(False)
    assert float(f(fa, jnp.asarray(lo))) == wide  # before the pull-up: the wide threshold
    assert float(f(t, jnp.asarray(3.0))) == wide
    assert float(f(t, jnp.asarray(lo))) == pytest.approx(final)
    assert float(f(t, jnp.asarray(0.05))) == pytest.approx(final)
    mid = 0.5 * (lo + hi)
    assert float(f(t, jnp.asarray(mid))) == pytest.approx(0.5 * (wide + final))
    # the reversal itself: a predicted crossrange 0.6 of the way from the final to the wide one
    m = ctx.model
    y = state_at(70e3, ctx)
    nav = EntryNav(y, *drag_and_lift(y, m.vehicle, m.earth, m.atmosphere))
    state = law.init(nav, ctx)._replace(phase=jnp.asarray(1), sign=jnp.asarray(1.0))
    fv = FlightVariables(jnp.asarray(7.5e3), jnp.asarray(0.0), 70e3, jnp.asarray(50.0))
    chi = final + 0.6 * (wide - final)  # target on the left while the bank turns right
    live = jnp.asarray(True)
    for pulled, ng, reverses in [(t, lo + 0.1 * (hi - lo), True), (t, hi, False), (fa, lo, False)]:
        sign, reverse = bank_sign(
            law,
            state,
            jnp.asarray(1),
            fv,
            jnp.asarray(chi),
            jnp.asarray(0.0),
            live,
            pulled,
            jnp.asarray(ng),
        )
        assert bool(reverse) == reverses and float(sign) == (-1.0 if reverses else 1.0)


def test_a_reference_without_a_kepler_phase_is_switched_to_on_speed(law_and_ctx, flight):
    """``apogee_switch = "speed"`` (the default) with a reference whose switch point is an
    apogee: a pulled-up first entry starts tracking at the reference's switch speed, climbing
    or not, and not before; a Kepler arc that ends faster than that goes back to the first
    entry (the predictor flies it so), one that ends slower starts tracking. In the predictor
    the same reference is flown from the switch speed to the chute: no prediction ends at a
    Kepler switch point (eq. 10 expands around an apogee there)."""
    _, law, ctx = law_and_ctx
    ref = law.reference
    apogee = eqx.tree_at(lambda g: g.reference.drag_load_g, law, ref.drag_load_g.at[0].set(0.6))
    assert bool(switch_by_speed(apogee)) and not bool(switch_by_speed(law))
    m = ctx.model
    y = state_at(61.6e3, ctx)
    nav = EntryNav(y, *drag_and_lift(y, m.vehicle, m.earth, m.atmosphere))
    live = jnp.asarray(True)
    v_sw = float(ref.switch_velocity_mps)
    cases = [  # (phase, pulled, speed above v_sw, hdot, load) -> phase
        (1, True, 50.0, -5.0, 1.5, 1),  # descending but faster than v_sw: first entry
        (1, True, -10.0, 20.0, 1.5, 3),  # climbing, at v_sw: tracking
        (1, False, -10.0, -20.0, 1.5, 1),  # not pulled up: first entry
        (2, True, 80.0, -5.0, 0.25, 1),  # Kepler arc ends fast: back to the first entry
        (2, True, -5.0, -5.0, 0.25, 3),  # Kepler arc ends slow: tracking
        (2, True, -5.0, 5.0, 0.1, 2),  # still in the arc
    ]
    for phase0, pulled, dv, hdot, ng, want in cases:
        state = apogee.init(nav, ctx)._replace(
            phase=jnp.asarray(phase0),
            pulled_up=jnp.asarray(pulled),
            dip_altitude_m=jnp.asarray(61.6e3 if pulled else 62.5e3),
        )
        fv = FlightVariables(jnp.asarray(v_sw + dv), jnp.asarray(0.0), 62e3, jnp.asarray(hdot))
        phase, *_ = phase_events(apogee, state, fv, jnp.asarray(ng), live)
        assert int(phase) == want, (phase0, pulled, dv, hdot, ng)
    # predictions of the flight's corrector cycles: the packaged (Kepler) reference ends some
    # at the switch point; the same cycles with an apogee reference all fly to the chute
    y, t, up, sigma, model = _corrector_cycles(law_and_ctx, flight, every=8)
    kinds = {}
    for g in (law, apogee):
        batch = jax.vmap(
            lambda g, y, t, u, s, m: predict(g, y, t, u, s, m, ctx.target_fixed),
            in_axes=(None, 0, 0, 0, 0, 0),
        )
        p = jax.jit(batch)(g, y, t, up, jnp.asarray(sigma), model)
        kinds[g is law] = set(np.asarray(p.kind).tolist())
    assert 0 in kinds[True]
    assert kinds[False] <= {1, 2, 4} and 1 in kinds[False]


def test_a_predicted_dive_ends_short_instead_of_diverging(law_and_ctx):
    """A full lift-down profile of a high-L/D run (the measured ratios of a -5.3 deg run with
    lift +22 %, drag -12 %) from 64 km, 11 km/s, -3.5 deg dives through 40 g. At 16 s steps
    RK4 then diverges: unguarded (``predictor_dive_load_g`` 1000 g) it returns nonsense (a
    'switch point' 24,000 km short, or a skip-out, as a -5.3 deg run's corrector read full
    lift down before flying it into the ground at 52 g). The guard ends it as a dive (kind 4),
    finite and short of the target like the same prediction at 1 s steps (which lands)."""
    from gnc_jax.dynamics.entry import EntryState
    from gnc_jax.guidance.entry.base import EntryModel

    _, law, ctx = law_and_ctx
    c = ctx.model
    model = EntryModel(c.vehicle, c.earth, c.atmosphere, jnp.asarray(0.824), jnp.asarray(1.151))
    y0 = entry_state_from_conditions(
        EntryConditions(64e3, 11.0e3, np.radians(-3.5), 0.6, 1.0, 0.2), c.earth
    )
    y = EntryState(y0.r, y0.v)

    @jax.jit
    def lift_down(g):
        pull = jnp.asarray(False)
        return predict(g, y, 0.0, pull, jnp.radians(180.0), model, ctx.target_fixed)

    def with_loads(dive_g, fraction):  # leaves of the same dtype: one lift_down program
        g = eqx.tree_at(lambda g: g.predictor_dive_load_g, law, jnp.asarray(float(dive_g)))
        return eqx.tree_at(lambda g: g.predictor_load_fraction, g, jnp.asarray(float(fraction)))

    # the numerical guard alone (20 g), the capsule's 10 g limit left out of the predictions
    guarded_law = with_loads(law.predictor_dive_load_g, 100.0)
    unguarded = with_loads(1000.0, 100.0)
    guarded, diverged = lift_down(guarded_law), lift_down(unguarded)
    fine = lift_down(dataclasses.replace(unguarded, predictor_dt_s=1.0, predictor_coast_dt_s=1.0))
    assert int(fine.kind) == 1 and float(fine.miss_m) < -1000e3  # lands far short
    assert int(guarded.kind) == 4
    np.testing.assert_allclose(float(guarded.miss_m), float(fine.miss_m), rtol=0.1)
    assert int(diverged.kind) != 1  # the 16 s steps without the guard: not a landing
    # the packaged law: a dive at 90 % of the capsule's limit already, earlier, shorter
    limited = lift_down(law)
    assert int(limited.kind) == 4 and float(limited.miss_m) < float(guarded.miss_m)
