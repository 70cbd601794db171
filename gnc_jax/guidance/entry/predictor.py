"""The skip-entry law's predictor (seed 003 §3.1): the range error of a first-entry bank
profile, by integrating the vertical-plane dynamics ahead.

The profile is |sigma|(v) = sigma_0 + (sigma_f - sigma_0) (v_0 - v)/(v_0 - v_sw), linear in
Earth-relative speed from the current speed v_0 to the reference switch speed v_sw. A
prediction runs up to the second-entry (switch) point and adds the second-entry range by the
first-order expansion of eq. 10 around the stored reference; after the pull-up it may fly on
to the chute for the crossrange there (``predictor_horizon``). A second entry it flies (after
a skip without a Kepler phase, or flown on) flies the bank the tracking will command
(``second_entry_bank``). The on-board model it flies is
scaled by the filtered ratios of measured to modelled drag and lift (:func:`filter_ratios`).
Each function takes the law (:class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance`) for
its settings and reference; the corrector (:mod:`gnc_jax.guidance.entry.corrector`) drives the
loop state of :func:`predictor_start` and :func:`predictor_step` itself.
"""

from typing import NamedTuple

import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from ..._numerics import computed_once, lanes_per_device
from ..._types import Array, Scalar
from ...dynamics.entry import EntryState, EntryStateXYZ, from_xyz, to_xyz
from ...geometry.sphere import (
    along_cross_track,
    crossrange_to_target,
    to_earth_fixed,
    to_inertial,
    unit,
)
from ...integrate import rk4_step
from .base import (
    EntryGuidanceContext,
    EntryModel,
    EntryNav,
    altitude_speed_hdot,
    drag_and_lift,
    flight_variables,
    hermite_crossing,
)
from .phases import apogee_gate, is_direct, load_relief, skip_switch, switch_by_speed
from .state import SkipEntryState


class Prediction(NamedTuple):
    """Outcome of one predictor run. The crossrange at the switch point includes the drift the
    rotating Earth adds under the Kepler arc, which the first-entry bank reversals use."""

    miss_m: Scalar  # predicted range error (> 0 overshoot)
    crossrange_m: Scalar  # crossrange to the target at the end point (> 0 target on the left)
    kind: Array  # 0 switch point reached, 1 chute reached without skip, 2 skip-out/time-out,
    # 4 a dive (the load beyond dive_load_g: ends short, at the last step's start)
    steps: Array  # integration steps used


class _Point(NamedTuple):
    """A predictor state with what the end-point location needs: altitude (m), Ḣ (m/s) and
    sensed load (g), and the Earth-relative speed (m/s) the midpoint bank extrapolates."""

    y: EntryStateXYZ
    altitude_m: Scalar
    hdot_mps: Scalar
    ng: Scalar
    speed_mps: Scalar


class _Origin(NamedTuple):
    """Where the predictions of a corrector cycle start: the navigated state (a
    :class:`_Point`), the density there, the Earth-relative speed v_0 of the profile's start,
    the time and the pull-up logic's state."""

    point: _Point
    density: Scalar
    speed_mps: Scalar
    t: Scalar
    pulled_up: Array
    dip_altitude_m: Scalar


class _PredictorState(NamedTuple):
    """Loop state of a prediction. ``now`` is the state reached, ``dy`` its derivative with
    the bank at ``now`` (the next step's first stage), ``before`` the state one step earlier:
    the end point (switch or chute) is located inside that last step after the loop."""

    now: _Point
    dy: EntryStateXYZ
    cos_bank: Scalar  # cosine of the bank flown from ``now``
    before: _Point
    t: Scalar  # time of ``now``
    dt: Scalar  # length of the step from ``before`` to ``now``
    pulled_up: Array
    dip_altitude_m: Scalar
    kepler: Array
    second: Array
    kind: Array  # -1 running, else that of Prediction (3: inactive, no step taken)
    k: Array
    # the step in which the switch point fell (before, now, time of now, length), whether it
    # has, and whether the prediction flies on from it (started after the pull-up), for a
    # ``predictor_horizon`` that flies on to the chute; else None
    switch_step: tuple | None = None


def profile(law, sigma_0, v_0, speed):
    """|sigma|(v) of the first entry: linear in speed from sigma_0 at v_0 to sigma_f; in the
    direct mode the constant sigma_0."""
    if is_direct(law):
        return sigma_0 + jnp.zeros_like(speed)
    v_sw = law.reference.switch_velocity_mps
    span = jnp.maximum(v_0 - v_sw, 1.0)
    s = jnp.clip((v_0 - speed) / span, 0.0, 1.0)
    return sigma_0 + (law.reference.first_entry_bank_rad - sigma_0) * s


def filter_ratios(law, state: SkipEntryState, nav: EntryNav, ng, ctx: EntryGuidanceContext):
    """Ratios of the measured drag and lift to those of the on-board model at the
    navigated state, first-order filtered (gain ``ctx.ratio_filter_gain`` per step) while
    the sensed load ``ng`` exceeds 0.05 g; the predictor scales its model by them."""
    m = ctx.model
    drag_model, lift_model = drag_and_lift(nav.y, m.vehicle, m.earth, m.atmosphere)
    sensing = ng > 0.05
    k = ctx.ratio_filter_gain
    drag_ratio = jnp.where(
        sensing,
        state.drag_ratio + k * (nav.drag_mps2 / jnp.maximum(drag_model, 1e-12) - state.drag_ratio),
        state.drag_ratio,
    )
    lift_ratio = jnp.where(
        sensing,
        state.lift_ratio + k * (nav.lift_mps2 / jnp.maximum(lift_model, 1e-12) - state.lift_ratio),
        state.lift_ratio,
    )
    return drag_ratio, lift_ratio


def predict(
    law,
    y: EntryState,
    t,
    pulled_up,
    sigma_0,
    model: EntryModel,
    target_fixed,
    active=True,
    dip_altitude_m=None,
    checkpoints: int | None = None,
) -> Prediction:
    """Predicted range error of the bank profile ``sigma_0`` (seed 003 §3.1), m.

    Integrates the vertical-plane dynamics (RK4, ``predictor_dt_s``; ``predictor_coast_dt_s``
    at low load) from ``(y, t)`` with
    the first-entry profile. The prediction normally stops at the switch point — the end of
    the Kepler phase: after the pull-up the load fell below ``kepler_load_g`` and has just
    risen above it again — and returns S2(eq. 10 at the switch state) minus the range
    from the switch point to the target. A skip too shallow to reach the Kepler phase has
    no such point: from its apogee the prediction flies the reference bank profile down to
    the chute and returns the signed along-track miss of the chute point; so does a
    prediction that never pulls up (rises ``pull_up_rise_m`` above the lowest altitude:
    ``dip_altitude_m`` so far, or the start's). A climb above ``skip_out_altitude_m`` or
    running out of steps returns a large overshoot. Under ``vmap`` the ``while_loop`` runs
    while one active run still integrates; an inactive run does no step.

    The state is integrated as components, each step reusing the derivative evaluated at
    the end of the previous one (four right-hand sides per step, the fourth also giving
    the load); the end point is located inside the last step once, after the loop.

    ``checkpoints`` (static): the steps are equinox's checkpointed ``while_loop`` (the same
    steps and arithmetic, reverse-mode differentiable), that many step carries kept.
    """
    origin = prediction_origin(law, y, t, pulled_up, model, dip_altitude_m)
    cond = lambda c: integrating(law, c)  # noqa: E731
    body = lambda c: predictor_step(law, c, sigma_0, origin.speed_mps, model)  # noqa: E731
    init = predictor_start(law, origin, sigma_0, active, model)
    if checkpoints is None:
        c = jax.lax.while_loop(cond, body, init)
    else:
        c = eqxi.while_loop(
            cond,
            body,
            init,
            max_steps=law.predictor_max_steps,
            kind="checkpointed",
            checkpoints=checkpoints,
        )
    return finished_prediction(law, c, y, t, model, target_fixed)


def prediction_origin(law, y: EntryState, t, pulled_up, model, dip_altitude_m=None) -> _Origin:
    """Where the predictions of a corrector cycle start from."""
    y_xyz = to_xyz(y)
    alt, v_0, hdot = altitude_speed_hdot(y_xyz, model.earth)
    density = model.atmosphere.density(alt)
    return _Origin(
        point=_Point(y_xyz, alt, hdot, model.load_g_xyz(density, v_0), v_0),
        density=density,
        speed_mps=v_0,
        t=jnp.asarray(t, float),
        pulled_up=jnp.asarray(pulled_up),
        dip_altitude_m=alt if dip_altitude_m is None else jnp.minimum(dip_altitude_m, alt),
    )


def predictor_start(law, o: _Origin, sigma_0, active, model) -> _PredictorState:
    """The loop state of a prediction of ``sigma_0`` before its first step (an inactive
    one is finished: it takes no step)."""
    p = o.point
    cos_b = jnp.cos(profile(law, sigma_0, o.speed_mps, o.speed_mps))
    cos_b = relieved(law, cos_b, o.pulled_up, p.ng, p.altitude_m, p.hdot_mps, model, o.density)
    dy, _ = model.vertical_plane_xyz(p.y, cos_b, density=o.density)
    f = jnp.asarray(False)
    return _PredictorState(
        now=o.point,
        dy=dy,
        cos_bank=cos_b,
        before=o.point,
        t=o.t,
        dt=jnp.zeros(()),
        pulled_up=o.pulled_up,
        dip_altitude_m=o.dip_altitude_m,
        kepler=f,
        second=f,
        kind=jnp.where(active, -1, 3).astype(jnp.int32),
        k=jnp.asarray(0, jnp.int32),
        switch_step=None
        if flies_to_switch(law)
        else (o.point, o.point, o.t, jnp.zeros(()), f, jnp.asarray(o.pulled_up)),
    )


def flies_to_switch(law) -> bool:
    """Whether every prediction ends at the switch point (``predictor_horizon = "switch"``)
    or, one started after the pull-up flying on to the chute, keeps the step in which it
    passed it (static)."""
    return law.predictor_horizon == "switch" or is_direct(law)


def integrating(law, c: _PredictorState):
    """The prediction has not ended and has steps left."""
    return (c.kind < 0) & (c.k < law.predictor_max_steps)


def second_entry_cos(law, speed, model):
    """Cosine of the bank a prediction flies in the second entry: the reference's, or with
    ``second_entry_bank = "tracked"`` the tracking's command without feedback (eq. 6:
    divided by the model's L/D over the reference's, at least ``track_bank_min``)."""
    cos_ref = jnp.cos(law.reference.bank_at(speed))
    if law.second_entry_bank == "reference":
        return cos_ref
    lim = jnp.cos(law.track_bank_min_rad)
    return jnp.clip(cos_ref * model.drag_ratio / model.lift_ratio, -lim, lim)


def predicted_cos_bank(law, second, sigma_0, v_0, speed, model):
    """Cosine of the bank the prediction flies: the first-entry profile's, or the second
    entry's after a skip without a Kepler phase or flown on from the switch (``second``)."""
    first = jnp.cos(profile(law, sigma_0, v_0, speed))
    return jnp.where(second, second_entry_cos(law, speed, model), first)


# The fences below pay from about 90 runs per device: each is a conditional the CPU runtime
# dispatches on its own, a latency per predictor step that a small batch does not earn back
# (lunar-skip-entry on both cores: 16 runs 0.42 -> 0.62 s fenced, 512 runs 1.94 -> 1.51 s).
FENCE_MIN_LANES = 96


def _once(law):
    """:func:`~gnc_jax._numerics.computed_once` for the predictor step of a batch known to
    have at least ``FENCE_MIN_LANES`` runs per device (a study's chunk); else the plain call
    (a batch of unknown size, e.g. a tuning step's: left as it was). The fence's live value
    is one of the law's parameters: a runtime scalar shared by the batch, as a fence needs,
    because the law is an argument of a study's compiled function (a law closed over as a
    constant folds the fence away: the same values, left to fusion)."""
    lanes = lanes_per_device()
    if lanes is None or lanes < FENCE_MIN_LANES:
        return lambda fn, *args: fn(*args)
    return lambda fn, *args: computed_once(fn, law.kepler_load_g, *args)


def predictor_step(law, c: _PredictorState, sigma_0, v_0, model) -> _PredictorState:
    """One RK4 step of the prediction and its phase logic. The bank is held over the step
    at its value at the step's start (``predictor_bank = "step"``, a first-order error in
    the step), or at the speed extrapolated linearly from the last step to the middle of
    this one (``"midpoint"``: second order, as the midpoint rule; the first step of a
    prediction, which has no last step, holds the start's), or follows the profile at
    every stage (``"stage"``).

    The step is ``predictor_dt_s``, or ``predictor_coast_dt_s`` while the load is below
    ``predictor_coast_load_g`` (the high part of the Kepler arc)."""
    dt = law.predictor_dt_s
    if law.predictor_coast_dt_s != dt:
        dt = jnp.where(c.now.ng < law.predictor_coast_load_g, law.predictor_coast_dt_s, dt)
    # Each stage's right-hand side, the phase logic and the next step's bank are computed
    # once into memory (computed_once): left to fusion, XLA on CPU recomputes a value in
    # every consumer's loop: the stage's density, speed and lift direction in each of the
    # six derivative components, the phase flags in every carried array they select, the
    # bank's profile lookups in the next right-hand side's components (measured: a
    # 512-run lunar-skip-entry study 22 % faster, 2,537 -> 1,749 elementwise operations per
    # run and predictor step; the last bits of the outcomes move).
    once = _once(law)

    def field(t, y, _):
        if law.predictor_bank == "stage":  # the profile at this stage's speed
            # (the load relief judged at the step's start, held over the step)
            now = c.now

            def rhs(y):
                speed = altitude_speed_hdot(y, model.earth)[1]
                cos_b = predicted_cos_bank(law, c.second, sigma_0, v_0, speed, model)
                cos_b = relieved(
                    law, cos_b, c.pulled_up, now.ng, now.altitude_m, now.hdot_mps, model
                )
                return model.vertical_plane_xyz(y, cos_b)[0]

            return once(rhs, y)
        return once(lambda y: model.vertical_plane_xyz(y, c.cos_bank)[0], y)

    y1 = rk4_step(field, c.t, c.now.y, dt, k1=c.dy)
    alt1, speed1, hdot1 = altitude_speed_hdot(y1, model.earth)
    density1 = model.atmosphere.density(alt1)
    ng1 = model.load_g_xyz(density1, speed1)
    dip, pulled, kepler, second, first, kind = once(
        lambda *a: _phases(law, c, *a), alt1, hdot1, ng1, speed1
    )
    switch_step = c.switch_step
    if first is not None:  # fly on from the switch point with the second entry's bank
        before, now, t_sw, dt_sw, passed, flies_on = switch_step
        now1 = _Point(y1, alt1, hdot1, ng1, speed1)
        keep = lambda a, b: jax.tree_util.tree_map(  # noqa: E731
            lambda x, y: jnp.where(first, y, x), a, b
        )
        switch_step = keep(
            (before, now, t_sw, dt_sw, passed, flies_on),
            (c.now, now1, c.t + dt, dt, first, flies_on),
        )
    cos_b1 = once(
        lambda *a: _next_bank(law, c, dt, sigma_0, v_0, model, *a),
        alt1,
        hdot1,
        ng1,
        speed1,
        dip,
        pulled,
        kepler,
        second,
        density1,
    )
    dy1, _ = model.vertical_plane_xyz(y1, cos_b1, density=density1)
    return _PredictorState(
        now=_Point(y1, alt1, hdot1, ng1, speed1),
        dy=dy1,
        cos_bank=cos_b1,
        before=c.now,
        t=c.t + dt,
        dt=jnp.asarray(dt, float),
        pulled_up=pulled,
        dip_altitude_m=dip,
        kepler=kepler,
        second=second,
        kind=kind,
        k=c.k + 1,
        switch_step=switch_step,
    )


def _phases(law, c: _PredictorState, alt1, hdot1, ng1, speed1):
    """The phase logic of :func:`predictor_step` at the step's end point:
    ``(dip, pulled, kepler, second, first, kind)``, ``first`` (the step passed the first
    switch point of a prediction flown on from it) ``None`` when the prediction ends
    there."""
    dip = jnp.where(c.pulled_up, c.dip_altitude_m, jnp.minimum(c.dip_altitude_m, alt1))
    pulled = c.pulled_up | (alt1 > dip + law.pull_up_rise_m)
    kepler = c.kepler | (pulled & (ng1 < law.kepler_load_g))
    descending = pulled & (hdot1 < 0.0) & (ng1 >= law.kepler_load_g)
    by_speed = switch_by_speed(law)
    switch = kepler & descending & ~by_speed
    # a reference switching on speed is flown from its switch speed, Kepler arc or not
    on_speed = pulled & (speed1 <= law.reference.switch_velocity_mps)
    crest = ~kepler & skip_switch(law, pulled, hdot1, ng1, speed1)
    second = c.second | jnp.where(by_speed, on_speed, crest)
    first = None
    if not flies_to_switch(law):  # fly on from the switch point with the second entry's bank
        _, _, _, _, passed, flies_on = c.switch_step
        # the first switch point of a prediction started after the pull-up (a skip flown on
        # may skip again); one started before it ends there
        first = switch & ~passed & flies_on
        second = second | first
        kepler = kepler & ~first
        switch = switch & ~flies_on
    if is_direct(law):  # down to the chute on the constant bank
        kepler = switch = second = jnp.zeros_like(kepler)
    chute = alt1 < law.chute_altitude_m
    skip = alt1 > law.skip_out_altitude_m
    dive = ~(ng1 <= dive_load_g(law))  # (a NaN state too)
    kind = jnp.where(switch, 0, jnp.where(chute, 1, jnp.where(skip, 2, -1)))
    kind = jnp.where(dive, 4, kind).astype(jnp.int32)
    return dip, pulled, kepler, second, first, kind


def dive_load_g(law):
    """The load (g) beyond which a prediction is a dive and ends short: the numerical guard
    ``predictor_dive_load_g``, or in a skip ``predictor_load_fraction`` of the capsule's load
    limit where that is lower (none for a mission without one). A direct entry keeps the
    guard alone: its reach is designed within 90 % of the limit already, and the targets at
    its short end ask for loads near it (see ``predictor_load_fraction``)."""
    if is_direct(law):
        return law.predictor_dive_load_g
    return jnp.minimum(law.predictor_dive_load_g, law.predictor_load_fraction * law.load_limit_g)


def _next_bank(law, c: _PredictorState, dt, sigma_0, v_0, model, *end):
    """Cosine of the bank :func:`predictor_step` flies in the next step, from the step's end
    point ``end`` = ``(alt1, hdot1, ng1, speed1, dip, pulled, kepler, second, density1)``:
    the profile's (:func:`predicted_cos_bank`, blended at an apogee switch), or full lift up
    where the law's load relief would fly it (:func:`~.phases.load_relief`)."""
    alt1, hdot1, ng1, speed1, dip, pulled, kepler, second, density1 = end
    speed_bank = speed1
    if law.predictor_bank == "midpoint":  # the speed half-way through the next step
        dt_next = law.predictor_dt_s
        if law.predictor_coast_dt_s != dt_next:
            dt_next = jnp.where(ng1 < law.predictor_coast_load_g, law.predictor_coast_dt_s, dt_next)
        speed_bank = speed1 + (0.5 * dt_next / dt) * (speed1 - c.now.speed_mps)
    cos_b1 = predicted_cos_bank(law, second, sigma_0, v_0, speed_bank, model)
    if law.predictor_apogee == "blend" and not is_direct(law):
        cos_b1 = apogee_blend(
            law,
            cos_b1,
            c.now,
            dt,
            alt1,
            hdot1,
            ng1,
            speed1,
            speed_bank,
            dip,
            pulled,
            kepler,
            second,
            model,
        )
    return relieved(law, cos_b1, pulled, ng1, alt1, hdot1, model, density1)


def relieved(law, cos_bank, pulled, ng, altitude_m, hdot_mps, model, density=None):
    """``cos_bank``, or 1 (full lift up) where the law's load relief flies it (``density``
    at ``altitude_m``: evaluated there when ``None``)."""
    relief = load_relief(law, pulled, ng, altitude_m, hdot_mps, model.atmosphere, density)
    return cos_bank if relief is None else jnp.where(relief, 1.0, cos_bank)


def apogee_blend(
    law,
    cos_b1,
    now,
    dt_taken,
    alt1,
    hdot1,
    ng1,
    speed1,
    speed_bank,
    dip,
    pulled,
    kepler,
    second,
    model,
):
    """Cosine of the bank of the step from ``1`` (``predictor_apogee = "blend"``): a step
    that will reach the switch of a skip without a Kepler phase (its apogee, or the
    reference's switch speed when ``_by_speed``), where the prediction changes to the
    reference bank, flies the first-entry cosine ``cos_b1`` for the fraction of the step
    before the switch and the reference's after it. The time to the switch is Hdot (or
    the speed above the switch speed) over its rate of fall in the step just taken (from
    ``now``, of ``dt_taken``); the vertical lift is linear in the cosine, so the step's
    lift impulse is that of a change at the switch to first order, and the range error no
    longer jumps by a step of the wrong bank as sigma_0 moves the switch across a step's
    end."""
    dt = law.predictor_dt_s
    if law.predictor_coast_dt_s != dt:
        dt = jnp.where(ng1 < law.predictor_coast_load_g, law.predictor_coast_dt_s, dt)
    # time to the switch: to the reference's switch speed, or to the apogee
    decel = (now.speed_mps - speed1) / dt_taken
    tau_speed = (speed1 - law.reference.switch_velocity_mps) / jnp.where(decel > 0.0, decel, 1.0)
    fall = (now.hdot_mps - hdot1) / dt_taken  # -dHdot/dt over the step just taken
    tau_apogee = hdot1 / jnp.where(fall > 0.0, fall, 1.0)
    by_speed = switch_by_speed(law)
    tau = jnp.where(by_speed, tau_speed, tau_apogee)
    coming = jnp.where(
        by_speed,
        (tau_speed > 0.0) & (decel > 0.0),
        (hdot1 > 0.0) & (fall > 0.0) & apogee_gate(law, speed1),
    )
    at_switch = pulled | (alt1 + 0.5 * hdot1 * tau > dip + law.pull_up_rise_m)
    no_kepler = ~kepler & (ng1 >= law.kepler_load_g)
    blend = ~second & (by_speed | no_kepler) & coming & (tau < dt) & at_switch
    f = jnp.clip(tau / dt, 0.0, 1.0)
    cos_ref = second_entry_cos(law, speed_bank, model)
    return jnp.where(blend, f * cos_b1 + (1.0 - f) * cos_ref, cos_b1)


def end_point(law, c: _PredictorState):
    """State and time where a finished prediction ends, inside its last step (a prediction
    that took no step: its start). The altitude of the end point is the chute's, or for
    the switch point that where the load crosses ``kepler_load_g`` on a log-linear
    interpolation in altitude (the load grows nearly exponentially with depth); the time
    fraction of that altitude is found on the cubic Hermite interpolant of the altitude,
    and the position there on that of the position (from the velocities at both ends),
    the velocity linearly. A linear interpolation of the load in time misplaces the switch
    point by kilometres at 16 s steps, in wiggles of the range error along sigma_0 that
    the corrector's 5 km tolerance does not absorb."""
    dt = law.predictor_dt_s if law.predictor_coast_dt_s == law.predictor_dt_s else c.dt
    a, b = c.before, c.now
    log_a, log_b = jnp.log(jnp.maximum(a.ng, 1e-30)), jnp.log(jnp.maximum(b.ng, 1e-30))
    w = jnp.clip(
        (jnp.log(law.kepler_load_g) - log_a) / jnp.where(log_b != log_a, log_b - log_a, 1.0),
        0.0,
        1.0,
    )
    level = jnp.where(
        c.kind == 0, a.altitude_m + w * (b.altitude_m - a.altitude_m), law.chute_altitude_m
    )
    s = hermite_crossing(a.altitude_m, a.hdot_mps, b.altitude_m, b.hdot_mps, dt, level)
    s = jnp.where(c.kind == 4, 0.0, s)  # a dive ends at the last step's start
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    r = jax.tree_util.tree_map(
        lambda ra, va, rb, vb: h00 * ra + h10 * dt * va + h01 * rb + h11 * dt * vb,
        a.y.r,
        a.y.v,
        b.y.r,
        b.y.v,
    )
    v = jax.tree_util.tree_map(lambda p, q: p + s * (q - p), a.y.v, b.y.v)
    t_end = jnp.where(c.k > 0, c.t - dt + s * dt, c.t)
    return from_xyz(EntryStateXYZ(r, v)), t_end


def finished_prediction(law, c: _PredictorState, y, t, model, target_fixed) -> Prediction:
    """Range error and crossrange of a finished prediction started at ``(y, t)``."""
    p = _prediction_at_end(law, c, y, t, model, target_fixed)
    if flies_to_switch(law):
        return p
    # flown on from a switch point: its range error and kind ("chute_crossrange"), and the
    # chute's crossrange unless the flight on ended otherwise
    before, now, t_sw, dt_sw, passed, _ = c.switch_step
    at = c._replace(before=before, now=now, t=t_sw, dt=dt_sw, kind=jnp.zeros_like(c.kind))
    sw = _prediction_at_end(law, at, y, t, model, target_fixed)
    chi = jnp.where(passed & (p.kind != 1), sw.crossrange_m, p.crossrange_m)
    if law.predictor_horizon == "chute":
        return Prediction(p.miss_m, chi, p.kind, p.steps)
    return Prediction(
        jnp.where(passed, sw.miss_m, p.miss_m), chi, jnp.where(passed, 0, p.kind), p.steps
    )


def _prediction_at_end(law, c: _PredictorState, y, t, model, target_fixed) -> Prediction:
    earth = model.earth
    y_end, t_end = end_point(law, c)
    kind = jnp.where(c.kind < 0, 2, c.kind)  # out of steps: treat as a skip-out
    r_e = earth.equatorial_radius_m
    # Signed along-track position of the end point relative to the target, on the great
    # circle from here to the target (> 0 beyond it): a long skip that passes over the
    # target must count as an overshoot, which an unsigned distance would not.
    here = unit(to_earth_fixed(y.r, t, earth.rotation_rate))
    end = unit(to_earth_fixed(y_end.r, t_end, earth.rotation_rate))
    beyond = r_e * along_cross_track(end, here, target_fixed)[0]
    s2 = law.reference.second_entry_range(flight_variables(y_end, earth))
    overshoot = 2.0 * law.reference.range_to_go_m[0] + 1.0e7
    landed = (kind == 1) | (kind == 4)
    miss = jnp.where(kind == 0, s2 + beyond, jnp.where(landed, beyond, overshoot))
    target = to_inertial(target_fixed, t_end, earth.rotation_rate)
    v_rel = y_end.v - jnp.cross(earth.angular_velocity(), y_end.r)
    chi = r_e * crossrange_to_target(y_end.r, v_rel, target)
    return Prediction(miss, chi, kind, c.k)


# Cost model of the predictions (steps_per_cycle): fractions of the paper scenario's flight
HORIZON_FRACTION = 0.56  # mean time to the switch point from a corrector cycle over the flight
COAST_FRACTION = 0.6  # of that horizon flown in the predictor's coast steps (load < 0.02 g)
PREDICTIONS_PER_CYCLE = 2.7  # mean predictions per corrector cycle (131 over 49 cycles)


def steps_per_cycle(section: dict, flight_s: float) -> float:
    """RK4 steps the predictions of one corrector cycle take in a flight of about
    ``flight_s`` seconds, from the law's validated scenario ``section``: about
    ``PREDICTIONS_PER_CYCLE`` predictions (at most ``1 + n_bracket + n_iter``), each
    integrating about ``HORIZON_FRACTION`` of the flight ahead (to the switch point),
    ``COAST_FRACTION`` of it in steps of ``predictor_coast_dt_s`` and the rest in steps of
    ``predictor_dt_s``, at most ``predictor_max_steps``. The fractions are those of the paper
    scenario (256 runs: flight 1250 s, switch at 827 s, 2.7 predictions per cycle, 48 steps
    per prediction)."""
    horizon_s = HORIZON_FRACTION * flight_s
    horizon = horizon_s * (
        (1.0 - COAST_FRACTION) / section["predictor_dt_s"]
        + COAST_FRACTION / section["predictor_coast_dt_s"]
    )
    horizon = min(horizon, section["predictor_max_steps"])
    slots = 1 + section["n_bracket"] + section["n_iter"]
    return min(PREDICTIONS_PER_CYCLE, slots) * horizon
