"""Combined skip-entry guidance of a lunar-return capsule (seed 003) — "the capsule law".

Phases (seed 003 §2, Fig. 1):

0. *hold*: a bank is held until the sensed load exceeds ``ng0`` (the designed first-entry bank,
   or the scenario's hold bank: ``hold_bank``);
1. *first entry*: numerical predictor-corrector. Every ``pc_period`` the predictor integrates
   the vertical-plane dynamics with the bank profile |sigma|(v) = sigma_0 + (sigma_f - sigma_0)
   (v_0 - v)/(v_0 - v_sw), linear in Earth-relative speed from the current speed v_0 to the
   reference switch speed v_sw, only up to the second-entry (switch) point, and adds the
   second-entry range by the first-order expansion of eq. 10 around the stored reference. The
   corrector (eqs. 11-15) solves for sigma_0 with the bounded regula falsi of
   :mod:`gnc_jax.root_finding`, a fixed-iteration ``lax`` loop;
2. *Kepler*: after the pull-up, while N_g < 0.2 g (no guidance: the command is held); a
   skip without a Kepler phase goes from 1 to 3 at its apogee, or, when the reference's own
   switch is an apogee, at the reference's switch speed (``apogee_switch``), where a Kepler
   arc that ends faster also goes back to 1;
3. *second entry*: reference-trajectory tracking, cos sigma_c = [(L/D)_0 cos sigma_0 + K.Delta]
   / (L/D) (eq. 6 without its repeated K.Delta, a typo) with the feedback of eq. 7 on the drag
   load N_gx, Ḣ, the range to go S and its rate; the reference bank profile is corrected once
   at the switch point by eqs. 16-17 (switch-point compensation).

The sign of the bank follows bank reversals inside a crossrange funnel that narrows with speed.
In the direct mode a load relief (not in the seed: ``load_relief``) flies full lift up after
the first pull-up while the sensed load, extrapolated a few seconds ahead, nears the
capsule's load limit; the predictor flies the same rule.
Phase changes are hard logic (evaluation); gradients of the tracking gains flow through the
second entry, which has no discrete logic apart from the reversals.

The law is the ``"skip_entry"`` member of the capsule family
(:class:`~gnc_jax.guidance.entry.base.AbstractEntryGuidance`): ``init(nav, ctx)`` gives a
:class:`SkipEntryState`, ``step(state, nav, t, ctx)`` the bank command (rad) and the next state.
From the accelerometer-measured drag and lift in ``nav`` it filters the ratios of measured to
modelled drag and lift (its predictor's model) and forms the load, drag load and L/D it
tracks. The outcome's diagnostics (predictions, corrector cycles and failures, reversals,
event times, switch state, skip apogee, skip-out) accumulate in the state's ``log``, an
:class:`~gnc_jax.guidance.entry.base.EntryGuidanceLog`, which also holds this step's
corrector diagnostics for the trace.

This module holds the law's ``init``/``step``; the pieces are in files that name themselves:
:mod:`~gnc_jax.guidance.entry.skip_entry_params` (its parameters and their checks),
:mod:`~gnc_jax.guidance.entry.predictor`, :mod:`~gnc_jax.guidance.entry.corrector`,
:mod:`~gnc_jax.guidance.entry.tracking`,
:mod:`~gnc_jax.guidance.entry.phases` (phase machine and reversals) and
:mod:`~gnc_jax.guidance.entry.state` (its state and diagnostics). The second-entry reference
(:class:`~gnc_jax.guidance.entry.reference.ReferenceTrajectory`) is designed by the capsule
system (:mod:`gnc_jax.systems.capsule.reference`) and handed to
:meth:`SkipEntryGuidance.from_config`.
"""

import jax.numpy as jnp

from ...dynamics.entry import G0
from ...geometry.sphere import (
    along_track_to_go,
    crossrange_to_target,
    range_rate_to_target,
    to_inertial,
)
from ...params import from_config
from ..base import register_law
from .base import (
    EntryGuidanceContext,
    EntryModel,
    EntryNav,
    flight_variables,
)
from .corrector import corrector_cycle
from .phases import bank_sign, hold_bank_rad, is_direct, load_relief, phase_events
from .predictor import filter_ratios, profile, steps_per_cycle
from .reference import EntryMission
from .skip_entry_params import SkipEntryParameters
from .state import SkipEntryState, initial_log, updated_log
from .tracking import switch_compensation, track

__all__ = ["SkipEntryGuidance", "SkipEntryState"]


@register_law("skip_entry")
class SkipEntryGuidance(SkipEntryParameters):
    """The combined predictor-corrector / reference-trajectory law of seed 003.

    Gains and thresholds are array leaves (differentiable); loop sizes are static. Its fields
    (gains, thresholds, options) and their checks are declared in
    :class:`~gnc_jax.guidance.entry.skip_entry_params.SkipEntryParameters`.
    """

    @classmethod
    def prediction_steps(cls, section, flight_s):
        """:func:`~gnc_jax.guidance.entry.predictor.steps_per_cycle`."""
        return steps_per_cycle(section, flight_s)

    @classmethod
    def reference_switch_load_g(cls, section) -> float:
        """The Kepler-phase load (g) of ``section``: the reference this law tracks switches
        where the load, having fallen below it after the pull-up, rises through it again."""
        return section["kepler_load_g"]

    @classmethod
    def predicted_load_limit_g(cls, section) -> float:
        """``predictor_dive_load_g`` of ``section``: a prediction whose load exceeds it ends
        short as a dive, so the corrector never settles on such a profile."""
        return section["predictor_dive_load_g"]

    @classmethod
    def entry_mode_of(cls, section) -> str:
        """The entry mode ``section`` asks for ("auto", "skip" or "direct")."""
        return section["entry_mode"]

    @classmethod
    def from_config(cls, section, config, ctx: EntryMission | None = None):
        """The law of a scenario, from the capsule system's :class:`EntryMission` ``ctx``
        (:func:`gnc_jax.systems.capsule.reference.law_mission`): the chute altitude (m),
        where guidance ends, the reference designed for the scenario and the entry mode it
        was designed for ("auto" resolved by the capsule system)."""
        if ctx is None:
            raise ValueError("the skip-entry law is built with the capsule's EntryMission")
        return from_config(
            cls,
            section,
            reference=ctx.reference,
            chute_altitude_m=ctx.chute_altitude_m,
            load_limit_g=jnp.asarray(ctx.load_limit_g, float),
            direct=ctx.entry_mode == "direct",
        )

    # ---- the guidance-law protocol ----
    def init(self, nav: EntryNav, ctx: EntryGuidanceContext) -> SkipEntryState:
        """Hold phase at t = 0, with the nominal first-entry bank as the corrector's guess."""
        z = jnp.zeros(())
        zi = jnp.zeros((), int)
        return SkipEntryState(
            phase=zi,
            pulled_up=jnp.asarray(False),
            dip_altitude_m=jnp.asarray(jnp.inf),
            sigma_0=self.reference.first_entry_bank_rad,
            sign=jnp.ones(()),
            bank_mag=hold_bank_rad(self, ctx),
            bank_offset=z,
            drag_ratio=jnp.ones(()),
            lift_ratio=jnp.ones(()),
            last_status=zi,
            predicted_crossrange=z,
            corrector_slope=jnp.full((), jnp.nan),
            plan_speed=jnp.full((), jnp.nan),
            step=zi,
            log=initial_log(nav),
        )

    def step(self, state: SkipEntryState, nav: EntryNav, t, ctx: EntryGuidanceContext):
        """One control step: phase logic, the corrector every ``pc_every`` steps, the bank
        magnitude of the phase and its sign. Returns ``(bank command in rad, new state)``.

        Guidance stops (the state freezes but for the ratio filter) once the navigated
        altitude is below ``chute_altitude_m``."""
        earth = ctx.model.earth
        y = nav.y
        fv = flight_variables(y, earth)
        ng = jnp.sqrt(nav.drag_mps2**2 + nav.lift_mps2**2) / G0
        drag_ratio, lift_ratio = filter_ratios(self, state, nav, ng, ctx)
        model = EntryModel(ctx.model.vehicle, earth, ctx.model.atmosphere, drag_ratio, lift_ratio)
        target = to_inertial(ctx.target_fixed, t, earth.rotation_rate)
        v_rel = y.v - jnp.cross(earth.angular_velocity(), y.r)
        to_go = earth.equatorial_radius_m * along_track_to_go(y.r, v_rel, target)
        live = ~(fv.altitude_m < self.chute_altitude_m)

        phase, pulled, dip, events = phase_events(self, state, fv, ng, live)
        bank_offset = jnp.where(
            events.to_track, switch_compensation(self, fv, to_go), state.bank_offset
        )
        correcting = live & (phase == 1)
        if is_direct(self):
            correcting = correcting & (fv.speed_mps > self.direct_final_speed_mps)
        res, did_pc = corrector_cycle(
            self, state, y, t, fv.speed_mps, ctx, model, pulled, correcting
        )
        sigma_0 = jnp.where(did_pc, res.x, state.sigma_0)
        chi_switch = jnp.where(did_pc, res.aux, state.predicted_crossrange)

        range_rate = earth.equatorial_radius_m * range_rate_to_target(y.r, v_rel, target)
        c_l0, c_d0 = ctx.model.vehicle.c_l, ctx.model.vehicle.c_d
        ld = nav.lift_mps2 / jnp.maximum(nav.drag_mps2, 1e-12)
        track_mag = track(
            self,
            fv.speed_mps,
            nav.drag_mps2 / G0,
            fv.hdot_mps,
            to_go,
            range_rate,
            ld / (c_l0 / c_d0),
            bank_offset,
        )
        mag = jnp.where(
            phase == 0,
            hold_bank_rad(self, ctx),
            jnp.where(
                phase == 1,
                profile(self, sigma_0, fv.speed_mps, fv.speed_mps),
                jnp.where(phase == 2, state.bank_mag, track_mag),
            ),
        )
        relief = load_relief(self, pulled, ng, fv.altitude_m, fv.hdot_mps, ctx.model.atmosphere)
        if relief is not None:  # full lift up: the magnitude 0, whatever the sign
            mag = jnp.where(live & (phase != 0) & relief, 0.0, mag)
        chi_now = earth.equatorial_radius_m * crossrange_to_target(y.r, v_rel, target)
        sign, reverse = bank_sign(self, state, phase, fv, chi_switch, chi_now, live, pulled, ng)

        log = updated_log(self, state, y, t, ctx, fv, phase, events, res, did_pc, reverse, live)
        new = SkipEntryState(
            phase=phase,
            pulled_up=pulled,
            dip_altitude_m=dip,
            sigma_0=sigma_0,
            sign=sign,
            bank_mag=mag,
            bank_offset=bank_offset,
            drag_ratio=drag_ratio,
            lift_ratio=lift_ratio,
            last_status=jnp.where(did_pc, res.status, state.last_status),
            predicted_crossrange=chi_switch,
            corrector_slope=jnp.where(did_pc, res.slope, state.corrector_slope),
            plan_speed=jnp.where(did_pc, fv.speed_mps, state.plan_speed),
            step=state.step + 1,
            log=log,
        )
        return sign * mag, new
