"""The skip-entry law's phase machine and bank reversals (seed 003 §2, Fig. 1).

Phases: 0 *hold* (a bank held until the sensed load exceeds ``ng0_g``), 1 *first entry*
(predictor-corrector), 2 *Kepler* (after the pull-up, while the load is below
``kepler_load_g``: the command is held), 3 *second entry* (reference tracking). A skip without
a Kepler phase goes from 1 to 3 at its apogee, or, when the reference's own switch is an apogee,
at the reference's switch speed (``apogee_switch``), where a Kepler arc that ends faster also
goes back to 1. The switch rules here are shared by the law and its predictor
(:mod:`gnc_jax.guidance.entry.predictor`), so that the predictor flies the phases the law will.

The sign of the bank follows bank reversals inside a crossrange funnel that narrows with speed;
the first entry judges the crossrange predicted at the switch point. Phase changes are hard
logic. Each function takes the law
(:class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance`) for its thresholds and
reference.
"""

from typing import NamedTuple

import jax.numpy as jnp

from ..._types import Array, Scalar
from .base import EntryGuidanceContext, FlightVariables
from .state import SkipEntryState


class PhaseEvents(NamedTuple):
    """This step's phase changes (each gated by the law being active)."""

    start: Array  # 0 -> 1: the load exceeded ng0
    to_kepler: Array  # 1 -> 2
    to_track: Array  # 1 or 2 -> 3: the switch point


def is_direct(law) -> bool:
    """Whether the law flies its direct-entry mode (static): no Kepler phase, no second
    entry (:mod:`gnc_jax.guidance.entry.direct`)."""
    return law.direct


def hold_bank_rad(law, ctx: EntryGuidanceContext) -> Scalar:
    """Bank magnitude of the hold phase (see ``hold_bank``), rad."""
    if law.hold_bank == "designed":
        return law.reference.first_entry_bank_rad
    return ctx.hold_bank_rad


def apogee_gate(law, speed):
    """Whether a descent without a Kepler phase at ``speed`` may start the second entry
    (see ``apogee_switch_margin_mps``): always, unless the reference's own switch point
    is an apogee and ``speed`` is more than the margin above its speed."""
    slow = speed <= law.reference.switch_velocity_mps + law.apogee_switch_margin_mps
    return slow | ~law.reference.switch_at_apogee(law.kepler_load_g)


def switch_by_speed(law):
    """Whether a skip without a Kepler phase switches on speed (see ``apogee_switch``)."""
    return (law.apogee_switch == "speed") & law.reference.switch_at_apogee(law.kepler_load_g)


def skip_switch(law, pulled, hdot, ng, speed):
    """Whether a first entry that has pulled up without a Kepler phase (the load has not
    fallen below ``kepler_load_g``) starts the second entry here: at the reference's
    switch speed when the reference's own switch is an apogee and ``apogee_switch`` is
    "speed", else at the first descending point (through :func:`apogee_gate`)."""
    held = pulled & (ng >= law.kepler_load_g)
    at_speed = speed <= law.reference.switch_velocity_mps
    at_apogee = (hdot < 0.0) & apogee_gate(law, speed)
    return held & jnp.where(switch_by_speed(law), at_speed, at_apogee)


def phase_events(law, state: SkipEntryState, fv: FlightVariables, ng, live):
    """Phase of this step (hard logic, seed 003 Fig. 1), the pull-up flag, the dip's
    altitude and the events."""
    phase = state.phase
    start = live & (phase == 0) & (ng > law.ng0_g)
    phase = jnp.where(start, 1, phase)
    dip = jnp.where(
        (phase >= 1) & ~state.pulled_up,
        jnp.minimum(state.dip_altitude_m, fv.altitude_m),
        state.dip_altitude_m,
    )
    pulled = state.pulled_up | ((phase >= 1) & (fv.altitude_m > dip + law.pull_up_rise_m))
    to_kepler = live & (phase == 1) & pulled & (fv.hdot_mps > 0.0) & (ng < law.kepler_load_g)
    phase = jnp.where(to_kepler, 2, phase)
    kepler_end = (phase == 2) & pulled & (fv.hdot_mps < 0.0) & (ng >= law.kepler_load_g)
    # (a reference switching on speed: a Kepler arc that ends faster than its switch
    # speed goes back to the first entry, as the predictor flies it)
    slow = ~switch_by_speed(law) | (fv.speed_mps <= law.reference.switch_velocity_mps)
    to_track = live & (
        (kepler_end & slow)
        | ((phase == 1) & skip_switch(law, pulled, fv.hdot_mps, ng, fv.speed_mps))
    )
    if is_direct(law):  # the first entry lasts down to the chute
        to_kepler = to_track = jnp.zeros_like(to_kepler)
        phase = jnp.where(start | (state.phase == 1), 1, state.phase)
    phase = jnp.where(live & kepler_end & ~slow, 1, phase)
    phase = jnp.where(to_track, 3, phase)
    return phase, pulled, dip, PhaseEvents(start, to_kepler, to_track)


def load_relief(law, pulled, ng, altitude_m, hdot_mps, atmosphere, density=None):
    """Whether the direct entry flies full lift up for load relief (``load_relief``): after
    the first pull-up, while the sensed load ``ng`` (g) extrapolated ``load_relief_lead_s``
    ahead (by the ``atmosphere``'s density ratio between ``altitude_m``, where it is
    ``density``, evaluated here when ``None``, and the altitude the sink rate ``hdot_mps``
    reaches in that time) exceeds ``load_relief_fraction`` of the capsule's load limit.
    Shared by the law and its predictor; ``None`` (static) when the relief is off or the law
    flies a skip."""
    if law.load_relief == "off" or not is_direct(law):
        return None
    if density is None:
        density = atmosphere.density(altitude_m)
    ahead = atmosphere.density(altitude_m + jnp.minimum(hdot_mps, 0.0) * law.load_relief_lead_s)
    limit = law.load_relief_fraction * law.load_limit_g
    return pulled & (ng * ahead > limit * density)


def switch_threshold_m(law, pulled, ng):
    """First-entry reversal threshold on the predicted switch-point crossrange, m:
    ``switch_crossrange_m``, narrowing after the pull-up linearly with the load from
    ``switch_narrow_load_g`` down to ``switch_crossrange_final_m`` at the Kepler load,
    where the first entry's last reversal is made."""
    w = jnp.clip(
        (ng - law.kepler_load_g) / jnp.maximum(law.switch_narrow_load_g - law.kepler_load_g, 1e-6),
        0.0,
        1.0,
    )
    narrowed = law.switch_crossrange_final_m + w * (
        law.switch_crossrange_m - law.switch_crossrange_final_m
    )
    return jnp.where(
        pulled, jnp.minimum(narrowed, law.switch_crossrange_m), law.switch_crossrange_m
    )


def funnel_m(law, speed):
    return law.funnel_base_m + law.funnel_quadratic_s2_m * speed**2


def bank_sign(law, state: SkipEntryState, phase, fv, chi_switch, chi_now, live, pulled, ng):
    """Sign of the bank and whether it reverses this step.

    The bank reverses when the crossrange leaves the funnel (phases 1 and 3); the first
    entry judges the crossrange predicted at the switch point, which includes the drift of
    the rotating Earth under the Kepler arc, against :func:`switch_threshold_m`."""
    if is_direct(law):  # no switch point: the funnel on the crossrange now, as the second entry
        chi, threshold = chi_now, funnel_m(law, fv.speed_mps)
    else:
        chi = jnp.where(phase == 1, chi_switch, chi_now)
        threshold = jnp.where(
            phase == 1, switch_threshold_m(law, pulled, ng), funnel_m(law, fv.speed_mps)
        )
    want = -jnp.sign(chi)  # negative bank turns left, towards a target on the left
    outside = (jnp.abs(chi) > threshold) & ((phase == 1) | (phase == 3))
    reverse = live & outside & (want != state.sign)
    return jnp.where(reverse, want, state.sign), reverse
