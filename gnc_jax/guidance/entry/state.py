"""The skip-entry law's state between control steps and the diagnostics it keeps.

:class:`SkipEntryState` is what :class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance`
carries from one control step to the next; its ``log``, an
:class:`~gnc_jax.guidance.entry.base.EntryGuidanceLog`, accumulates the outcome's diagnostics
(predictions, corrector cycles and failures, reversals, event times, switch state, skip
apogee, skip-out) and holds this step's corrector diagnostics for the trace.
"""

from typing import NamedTuple

import jax.numpy as jnp

from ..._types import Array, Scalar
from ...root_finding import RootStatus
from .base import EntryGuidanceLog, EntryNav, ground_range_m


class SkipEntryState(NamedTuple):
    """State of :class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance` between control
    steps.

    Attributes:
        phase: 0 hold, 1 predictor-corrector, 2 Kepler, 3 tracking.
        pulled_up: the vehicle has risen ``pull_up_rise_m`` above ``dip_altitude_m``.
        dip_altitude_m: lowest altitude since guidance started, until the pull-up, m.
        sigma_0: corrector solution, rad (start of the first-entry profile).
        sign: sign of the bank (+1 right, -1 left), flipped by the reversals.
        bank_mag: bank magnitude commanded last, rad (held through the Kepler phase).
        bank_offset: switch-point compensation of the reference bank (eqs. 16-17), rad.
        drag_ratio, lift_ratio: filtered ratios of measured to modelled drag and lift.
        last_status: :class:`~gnc_jax.root_finding.RootStatus` of the last corrector cycle.
        predicted_crossrange: crossrange at the switch point of the last corrector solution, m.
        corrector_slope: d(predicted range error)/d sigma_0 of the last corrector cycle (the
            secant through its last two predictions), m/rad; NaN before the first.
        plan_speed: Earth-relative speed at the last corrector solution, m/s (NaN before the
            first): the start v_0 of the profile it planned.
        step: control steps taken; the corrector runs when ``step % pc_every == 0``.
        log: the diagnostics of the outcome and the trace.
    """

    phase: Array
    pulled_up: Array
    dip_altitude_m: Scalar
    sigma_0: Scalar
    sign: Scalar
    bank_mag: Scalar
    bank_offset: Scalar
    drag_ratio: Scalar
    lift_ratio: Scalar
    last_status: Array
    predicted_crossrange: Scalar
    corrector_slope: Scalar
    plan_speed: Scalar
    step: Array
    log: EntryGuidanceLog


def initial_log(nav: EntryNav) -> EntryGuidanceLog:
    """The diagnostics at the entry interface: nothing counted yet, the entry position kept
    for the range flown."""
    z = jnp.zeros(())
    zi = jnp.zeros((), int)
    return EntryGuidanceLog(
        predictions=zi,
        cycle_predictions_max=zi,
        pc_cycles=zi,
        corrector_failures=zi,
        reversals=zi,
        predictor_steps=z,
        t_guidance_s=z,
        t_kepler_s=z,
        t_switch_s=z,
        switch=jnp.zeros(4),
        skip_apogee_m=z,
        skipped_out=jnp.asarray(False),
        entry_r_m=nav.y.r,
        step_predictions=zi,
        step_miss_m=z,
    )


def updated_log(
    law, state: SkipEntryState, y, t, ctx, fv, phase, events, res, did_pc, reverse, live
):
    """The diagnostics after this step (see :class:`EntryGuidanceLog`)."""
    log = state.log
    evals = jnp.where(did_pc, res.n_evals_early_exit, 0)
    range_flown = ground_range_m(log.entry_r_m, 0.0, y.r, t, ctx.model.earth)
    switch = jnp.stack([fv.speed_mps, fv.altitude_m, fv.hdot_mps, range_flown])
    kepler = (phase == 2) & live
    return EntryGuidanceLog(
        predictions=log.predictions + evals,
        cycle_predictions_max=jnp.maximum(log.cycle_predictions_max, evals),
        pc_cycles=log.pc_cycles + did_pc,
        corrector_failures=log.corrector_failures + (did_pc & (res.status != RootStatus.ok)),
        reversals=log.reversals + reverse,
        predictor_steps=log.predictor_steps + jnp.where(did_pc, res.cost, 0.0),
        t_guidance_s=jnp.where(events.start, t, log.t_guidance_s),
        t_kepler_s=jnp.where(events.to_kepler, t, log.t_kepler_s),
        t_switch_s=jnp.where(events.to_track, t, log.t_switch_s),
        switch=jnp.where(events.to_track, switch, log.switch),
        skip_apogee_m=jnp.where(
            kepler, jnp.maximum(log.skip_apogee_m, fv.altitude_m), log.skip_apogee_m
        ),
        skipped_out=log.skipped_out | (live & (fv.altitude_m > law.skip_out_altitude_m)),
        entry_r_m=log.entry_r_m,
        step_predictions=evals,
        step_miss_m=jnp.where(did_pc, res.f_x, 0.0),
    )
