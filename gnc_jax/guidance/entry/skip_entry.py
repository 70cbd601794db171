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
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..._types import Array, Scalar
from ...dynamics.entry import (
    G0,
    EntryState,
    EntryStateXYZ,
    entry_state_from_conditions,
    from_xyz,
    to_xyz,
)
from ...geometry.sphere import (
    along_cross_track,
    along_track_to_go,
    crossrange_to_target,
    range_rate_to_target,
    to_earth_fixed,
    to_inertial,
    unit,
)
from ...integrate import rk4_step
from ...params import from_config, param
from ...root_finding import RegulaFalsiResult, RootStatus, regula_falsi
from ...schema import ScenarioError
from ..base import register_law
from .base import (
    AbstractEntryGuidance,
    EntryGuidanceContext,
    EntryGuidanceLog,
    EntryModel,
    EntryNav,
    FlightVariables,
    altitude_speed_hdot,
    drag_and_lift,
    flight_variables,
    ground_range_m,
    hermite_crossing,
)
from .reference import ReferenceTrajectory

DEG = math.pi / 180.0  # math.radians(x) is x * DEG to the last bit
# Predictor steps a corrector cycle takes between two looks at which predictions ended (see
# SkipEntryGuidance.correct): a look costs about a step (a prediction's end and the next one's
# start, for every run of the batch) and a finished prediction waits for it half a round on
# average; at 16 s steps a 256-run chunk's corrector time is least at 8 (16: the same, 4: 7 %
# more).
ROUND_STEPS = 8


def _where(pick, new, old):
    return jax.tree_util.tree_map(lambda a, b: jnp.where(pick, a, b), new, old)


class Prediction(NamedTuple):
    """Outcome of one predictor run. The crossrange at the switch point includes the drift the
    rotating Earth adds under the Kepler arc, which the first-entry bank reversals use."""

    miss_m: Scalar  # predicted range error (> 0 overshoot)
    crossrange_m: Scalar  # crossrange to the target at the end point (> 0 target on the left)
    kind: Array  # 0 switch point reached, 1 chute reached without skip, 2 skip-out/time-out,
    # 4 a dive (the load beyond predictor_dive_load_g: ends short, at the last step's start)
    steps: Array  # integration steps used


class SkipEntryState(NamedTuple):
    """State of :class:`SkipEntryGuidance` between control steps.

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


class _PhaseEvents(NamedTuple):
    """This step's phase changes (each gated by the law being active)."""

    start: Array  # 0 -> 1: the load exceeded ng0
    to_kepler: Array  # 1 -> 2
    to_track: Array  # 1 or 2 -> 3: the switch point


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


@register_law("skip_entry")
class SkipEntryGuidance(AbstractEntryGuidance):
    """The combined predictor-corrector / reference-trajectory law of seed 003.

    Gains and thresholds are array leaves (differentiable); loop sizes are static.

    Attributes:
        reference: the designed second-entry reference.
        k_drag_load, k_hdot, k_range, k_range_rate: dimensionless multipliers of the
            speed-scheduled gain vector of eq. 7 (see :meth:`feedback_gains`).
        ng0_g: load that starts guidance (end of the attitude hold).
        kepler_load_g: Kepler-phase threshold, 0.2 g in the seed.
        bracket_step_rad: Δσ of eq. 15; range_tolerance_m: corrector tolerance on |ΔS|.
        bank_min_rad, bank_max_rad: corrector bounds.
        skip_out_altitude_m: a prediction climbing above it counts as a skip-out.
        funnel_base_m, funnel_quadratic_s2_m: crossrange funnel: the bank reverses when the
            crossrange to the target exceeds base + quadratic * speed^2 (m), which narrows
            with speed like the lateral reach of the lift (second entry).
        switch_crossrange_m: first-entry reversal threshold on the crossrange *predicted at
            the switch point* (which includes the drift of the rotating Earth under the
            Kepler arc), so that the second entry starts close to the target's plane.
        track_bank_min_rad: smallest bank magnitude (and largest, pi minus it) the second
            entry commands: a lift vector held straight up or down has no lateral component.
        chute_altitude_m: end of guidance.
    """

    reference: ReferenceTrajectory
    chute_altitude_m: Scalar
    k_drag_load: Scalar = param(
        1.0,
        lo=0.0,
        hi=100.0,
        doc="eq. 7: weight of the drag-load term of the predicted range",
        tunable=True,
    )
    k_hdot: Scalar = param(
        1.0,
        lo=0.0,
        hi=100.0,
        doc="eq. 7: weight of the Ḣ term of the predicted range",
        tunable=True,
    )
    k_range: Scalar = param(
        2.5,
        lo=0.0,
        hi=100.0,
        doc="eq. 7: overall gain on the range deviation (1 = dead-beat)",
        tunable=True,
    )
    k_range_rate: Scalar = param(
        0.5,
        lo=0.0,
        hi=100.0,
        doc="eq. 7: weight of the range-rate term of the predicted range",
        tunable=True,
    )
    ng0_g: Scalar = param(
        0.1, lo=0.0, lo_open=True, hi=5.0, units="g", doc="load that ends the attitude hold"
    )
    kepler_load_g: Scalar = param(
        0.2, lo=0.0, lo_open=True, hi=5.0, units="g", doc="Kepler-phase load threshold"
    )
    pull_up_rise_m: Scalar = param(
        1000.0,
        lo=0.0,
        hi=1e5,
        units="m",
        doc="rise above the bottom of the first dip that declares the pull-up (law and "
        "predictor); a second entry without a Kepler phase needs it first. A vehicle "
        "levelling off at the bottom of the dip (Hdot within a few m/s of 0 while a bank "
        "reversal rolls) has not pulled up: with a pull-up at Hdot > 0 alone, 4 of 256 runs at "
        "a -5.6 deg entry switched to tracking at the bottom of the dip and skipped out",
    )
    bracket_step_rad: Scalar = param(
        5.0,
        toml="bracket_step_deg",
        scale=DEG,
        lo=0.01,
        hi=90.0,
        units="deg",
        doc="Δσ of eq. 15",
    )
    range_tolerance_m: Scalar = param(
        5.0,
        toml="range_tolerance_km",
        scale=1e3,
        lo=0.001,
        hi=1000.0,
        units="km",
        doc="corrector tolerance on the predicted range error",
    )
    bank_min_rad: Scalar = param(
        0.0,
        toml="bank_min_deg",
        scale=DEG,
        lo=0.0,
        hi=180.0,
        units="deg",
        doc="corrector's smallest bank",
    )
    bank_max_rad: Scalar = param(
        180.0,
        toml="bank_max_deg",
        scale=DEG,
        lo=0.0,
        hi=180.0,
        units="deg",
        doc="corrector's largest bank",
    )
    skip_out_altitude_m: Scalar = param(
        300.0,
        toml="skip_out_altitude_km",
        scale=1e3,
        lo=130.0,
        hi=1e5,
        units="km",
        doc="a prediction climbing above it counts as a skip-out",
    )
    funnel_base_m: Scalar = param(
        0.5,
        toml="funnel_base_km",
        scale=1e3,
        lo=0.0,
        hi=1e3,
        units="km",
        doc="crossrange funnel half-width at zero speed",
    )
    funnel_quadratic_s2_m: Scalar = param(
        0.6,
        toml="funnel_quadratic_km",
        convert=lambda x: x * 1e3 / 1e6,
        lo=0.0,
        hi=1e3,
        units="km/(km/s)^2",
        doc="funnel half-width = base + quadratic * speed^2",
    )
    switch_crossrange_m: Scalar = param(
        40.0,
        toml="switch_crossrange_km",
        scale=1e3,
        lo=0.0,
        hi=1e3,
        units="km",
        doc="first-entry reversal threshold on the crossrange predicted at the switch point",
    )
    switch_crossrange_final_m: Scalar = param(
        10.0,
        toml="switch_crossrange_final_km",
        scale=1e3,
        lo=0.0,
        hi=1e3,
        units="km",
        doc="the first-entry reversal threshold at the Kepler load: after the pull-up it "
        "narrows linearly with the load from switch_crossrange_km at switch_narrow_load_g to "
        "this. The vertical-plane prediction leaves out the lateral lift still to come, so "
        "a run whose predicted crossrange creeps up to the threshold as the load falls "
        "enters the Kepler arc beyond it (50 km at a 40 km threshold), which a low-L/D "
        "capsule tracking near lift-up cannot remove",
    )
    switch_narrow_load_g: Scalar = param(
        1.0,
        lo=0.0,
        lo_open=True,
        hi=10.0,
        units="g",
        doc="load below which (after the pull-up) the first-entry reversal threshold narrows",
    )
    track_bank_min_rad: Scalar = param(
        15.0,
        toml="track_bank_min_deg",
        scale=DEG,
        lo=0.0,
        hi=89.0,
        units="deg",
        doc="second entry: smallest commanded bank magnitude",
    )
    predictor_dt_s: float = param(
        16.0,
        lo=0.01,
        hi=60.0,
        units="s",
        static=True,
        doc="RK4 step of the predictor (see benchmarks/entry_integrators.py)",
    )
    predictor_coast_dt_s: float = param(
        32.0,
        lo=0.01,
        hi=120.0,
        units="s",
        static=True,
        doc="RK4 step of the predictor while the load is below predictor_coast_load_g (the "
        "Kepler arc, where drag is small; see benchmarks/entry_integrators.py)",
    )
    predictor_coast_load_g: Scalar = param(
        0.02,
        lo=0.0,
        hi=5.0,
        units="g",
        doc="load below which the predictor takes its coast step (below the Kepler-phase load)",
    )
    predictor_dive_load_g: Scalar = param(
        20.0,
        lo=1.0,
        hi=1000.0,
        units="g",
        doc="a prediction whose load exceeds this is a dive and ends short, where its last "
        "step started (its range error the along-track miss there). A lift-down profile of "
        "a high-L/D run (-5.3 deg, L/D +40 %) dives to 40 g in the prediction; at 16 s "
        "steps RK4 then diverges (the speed to 1e7 m/s, 'above the skip-out altitude'), so "
        "full lift down read as a skip-out, the corrector flew it, and the capsule dove in "
        "at 52 g",
    )
    predictor_max_steps: int = param(1000, lo=10, hi=100000, doc="predictor step budget")
    predictor_bank: str = param(
        "midpoint",
        choices=("step", "midpoint", "stage"),
        doc="bank of the predicted profile over an RK4 step: 'step' (its value at the step's "
        "start, as flown between control steps: a first-order error in the step), 'midpoint' "
        "(its value at the speed extrapolated to the middle of the step from the last step: "
        "second order at no cost; at 16 s steps the range predictions are 0.7 times as far "
        "from 0.5 s steps as those of 'step' at 8 s, at 2/3 of the steps) or 'stage' (at "
        "every RK4 stage: fourth order, twice the cost per step); see "
        "benchmarks/entry_integrators.py",
    )
    predictor_apogee: str = param(
        "blend",
        choices=("step", "blend"),
        doc="how a prediction without a Kepler phase changes to the reference bank at its "
        "switch (the apogee, or the reference's switch speed: apogee_switch): at the end of "
        "the RK4 step in which it falls ('step': up to a step of the first-entry bank flown "
        "past it, a saw-tooth of ~100 km in the range error along sigma_0 at 16 s steps), or "
        "inside the step ('blend': a step that reaches it, by a linear extrapolation of Hdot "
        "or the speed, flies the cosines of both banks weighted by the times before and after "
        "it, so the range error is continuous in sigma_0 to first order)",
    )
    apogee_switch: str = param(
        "speed",
        choices=("apogee", "speed"),
        doc="when the reference's switch point is its apogee (a skip without a Kepler phase: "
        "short ranges), the second entry starts at the reference's switch speed after the "
        "pull-up ('speed': continuous in the bank profile, as the reference is scheduled on "
        "speed) or at the first descending point ('apogee'; see apogee_switch_margin_mps). "
        "A run that levels off near the apogee (Hdot within a few m/s of 0 for tens of "
        "seconds) has an apogee time that jumps with the smallest change of lift: at -5.3 "
        "deg / 6000 km its predicted range errors scattered by +-80 km along sigma_0",
    )
    hold_bank: str = param(
        "designed",
        choices=("designed", "scenario"),
        doc="bank held from the entry interface until the load reaches ng0_g: the designed "
        "first-entry bank of the reference ('designed', the corrector's first guess; the "
        "capsule rolls to it from the de-orbit attitude at the entry interface) or the "
        "scenario's guidance.hold_bank_deg ('scenario'). Near the overshoot boundary the hold "
        "decides the capture: at -5.3 deg the 40 s held at 60 deg, and the roll from it "
        "through lift-up to the corrector's first lift-down command, left runs that full "
        "lift down from the entry interface captures skipping out",
    )
    corrector_start: str = param(
        "bracket",
        choices=("bracket", "secant"),
        doc="corrector start: 'bracket' (the last solution, then the Δσ step of eq. 15, as the "
        "seed) or 'secant' (warm start on the last solution's planned profile, then a secant "
        "step on the last cycle's slope: 40 % fewer predictions, but where the range error has "
        "two roots it can settle on the lofting one; at a -5.6 deg entry 18 of 256 runs skip "
        "out against 5 with 'bracket')",
    )
    apogee_switch_margin_mps: Scalar = param(
        250.0,
        lo=0.0,
        hi=1e5,
        units="m/s",
        doc="a skip without a Kepler phase (the reference's switch point is its apogee: short "
        "ranges) switches to tracking at its apogee only if the speed there is at most this "
        "much above the reference's switch speed; a faster crest (a ripple deep in the "
        "atmosphere, 2-3 g, after a 1-3 km rise, where a run flying much lift down never "
        "skips) is flown through on the first-entry profile, in the law and its predictor, "
        "until the speed has fallen to that. At -5.6 deg / 4000 km the runs' apogees are "
        "within 140 m/s of the reference's; the 9 failed runs of 200 switched 250-1470 m/s "
        "above it, at 60-66 km, after corrector cycles that could not bracket. 1e5 disables it",
    )
    n_bracket: int = param(6, lo=1, hi=100, doc="bracketing steps of the corrector")
    n_iter: int = param(6, lo=1, hi=100, doc="regula-falsi iterations of the corrector")

    @classmethod
    def check(cls, section, config):
        if section["bank_min_deg"] >= section["bank_max_deg"]:
            raise ScenarioError(
                "guidance.skip_entry.bank_min_deg: must be < guidance.skip_entry.bank_max_deg"
            )
        if section["predictor_coast_load_g"] >= section["kepler_load_g"]:
            # the switch point (the load rising through kepler_load_g) is located in a step
            # of predictor_dt_s only if the coast steps stop below it
            raise ScenarioError(
                "guidance.skip_entry.predictor_coast_load_g: "
                f"{section['predictor_coast_load_g']:g} g; allowed: below "
                f"guidance.skip_entry.kepler_load_g = {section['kepler_load_g']:g} g"
            )
        altitude = config["entry"]["altitude_km"]
        if section["skip_out_altitude_km"] <= altitude:
            # the flight would count as a skip-out from its first step
            raise ScenarioError(
                f"guidance.skip_entry.skip_out_altitude_km: {section['skip_out_altitude_km']:g}"
                f" km; allowed: above entry.altitude_km = {altitude:g} km"
            )

    @classmethod
    def from_config(cls, section, config, ctx=None):
        """The law of a scenario, with the second-entry reference designed by
        :mod:`gnc_jax.guidance.entry.reference_design` for ``ctx`` (the capsule simulation data: the
        nominal vehicle, Earth, atmosphere, entry and target; cached on disk after the first
        design). The chute altitude is the entry's (``entry.chute_altitude_km``)."""
        from .reference_design import NominalProblem, reference_for

        e, ref = config["entry"], config["reference"]
        chute = jnp.asarray(e["chute_altitude_km"] * 1e3, dtype=jnp.float64)
        problem = NominalProblem(
            model=EntryModel(ctx.vehicle, ctx.earth, ctx.atmosphere),
            entry=entry_state_from_conditions(ctx.entry, ctx.earth),
            target_fixed=ctx.target_fixed,
            kepler_load_g=jnp.asarray(section["kepler_load_g"], dtype=jnp.float64),
            chute_altitude_m=chute,
            v_end_mps=jnp.asarray(ref["v_end_mps"], dtype=jnp.float64),
        )
        description = {
            "entry": e,
            "vehicle": config["vehicle"],
            "atmosphere": config["atmosphere"],
            "kepler_load_g": section["kepler_load_g"],
            "v_end_mps": ref["v_end_mps"],
        }
        reference, _ = reference_for(
            problem, description, w_margin=ref["w_margin"], steps=ref["design_steps"]
        )
        return from_config(cls, section, reference=reference, chute_altitude_m=chute)

    # ---- predictor (seed 003 §3.1) ----
    def profile(self, sigma_0, v_0, speed):
        """|sigma|(v) of the first entry: linear in speed from sigma_0 at v_0 to sigma_f."""
        v_sw = self.reference.switch_velocity_mps
        span = jnp.maximum(v_0 - v_sw, 1.0)
        s = jnp.clip((v_0 - speed) / span, 0.0, 1.0)
        return sigma_0 + (self.reference.first_entry_bank_rad - sigma_0) * s

    def predict(
        self,
        y: EntryState,
        t,
        pulled_up,
        sigma_0,
        model: EntryModel,
        target_fixed,
        active=True,
        dip_altitude_m=None,
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
        """
        origin = self._origin(y, t, pulled_up, model, dip_altitude_m)
        c = jax.lax.while_loop(
            lambda c: self._integrating(c),
            lambda c: self._predictor_step(c, sigma_0, origin.speed_mps, model),
            self._predictor_start(origin, sigma_0, active, model),
        )
        return self._prediction(c, y, t, model, target_fixed)

    def _origin(self, y: EntryState, t, pulled_up, model, dip_altitude_m=None) -> _Origin:
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

    def _predictor_start(self, o: _Origin, sigma_0, active, model) -> _PredictorState:
        """The loop state of a prediction of ``sigma_0`` before its first step (an inactive
        one is finished: it takes no step)."""
        cos_b = jnp.cos(self.profile(sigma_0, o.speed_mps, o.speed_mps))
        dy, _ = model.vertical_plane_xyz(o.point.y, cos_b, density=o.density)
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
        )

    def _integrating(self, c: _PredictorState):
        """The prediction has not ended and has steps left."""
        return (c.kind < 0) & (c.k < self.predictor_max_steps)

    def _apogee_gate(self, speed):
        """Whether a descent without a Kepler phase at ``speed`` may start the second entry
        (see ``apogee_switch_margin_mps``): always, unless the reference's own switch point
        is an apogee and ``speed`` is more than the margin above its speed."""
        slow = speed <= self.reference.switch_velocity_mps + self.apogee_switch_margin_mps
        return slow | ~self.reference.switch_at_apogee(self.kepler_load_g)

    def _by_speed(self):
        """Whether a skip without a Kepler phase switches on speed (see ``apogee_switch``)."""
        return (self.apogee_switch == "speed") & self.reference.switch_at_apogee(self.kepler_load_g)

    def _skip_switch(self, pulled, hdot, ng, speed):
        """Whether a first entry that has pulled up without a Kepler phase (the load has not
        fallen below ``kepler_load_g``) starts the second entry here: at the reference's
        switch speed when the reference's own switch is an apogee and ``apogee_switch`` is
        "speed", else at the first descending point (through :meth:`_apogee_gate`)."""
        held = pulled & (ng >= self.kepler_load_g)
        at_speed = speed <= self.reference.switch_velocity_mps
        at_apogee = (hdot < 0.0) & self._apogee_gate(speed)
        return held & jnp.where(self._by_speed(), at_speed, at_apogee)

    def _bank(self, second, sigma_0, v_0, speed):
        """Bank magnitude the prediction flies: the first-entry profile, or the reference
        after a skip without a Kepler phase (``second``)."""
        return jnp.where(second, self.reference.bank_at(speed), self.profile(sigma_0, v_0, speed))

    def _predictor_step(self, c: _PredictorState, sigma_0, v_0, model) -> _PredictorState:
        """One RK4 step of the prediction and its phase logic. The bank is held over the step
        at its value at the step's start (``predictor_bank = "step"``, a first-order error in
        the step), or at the speed extrapolated linearly from the last step to the middle of
        this one (``"midpoint"``: second order, as the midpoint rule; the first step of a
        prediction, which has no last step, holds the start's), or follows the profile at
        every stage (``"stage"``).

        The step is ``predictor_dt_s``, or ``predictor_coast_dt_s`` while the load is below
        ``predictor_coast_load_g`` (the high part of the Kepler arc)."""
        dt = self.predictor_dt_s
        if self.predictor_coast_dt_s != dt:
            dt = jnp.where(c.now.ng < self.predictor_coast_load_g, self.predictor_coast_dt_s, dt)

        def field(t, y, _):
            if self.predictor_bank == "stage":  # the profile at this stage's speed
                speed = altitude_speed_hdot(y, model.earth)[1]
                cos_b = jnp.cos(self._bank(c.second, sigma_0, v_0, speed))
                return model.vertical_plane_xyz(y, cos_b)[0]
            return model.vertical_plane_xyz(y, c.cos_bank)[0]

        y1 = rk4_step(field, c.t, c.now.y, dt, k1=c.dy)
        alt1, speed1, hdot1 = altitude_speed_hdot(y1, model.earth)
        density1 = model.atmosphere.density(alt1)
        ng1 = model.load_g_xyz(density1, speed1)
        dip = jnp.where(c.pulled_up, c.dip_altitude_m, jnp.minimum(c.dip_altitude_m, alt1))
        pulled = c.pulled_up | (alt1 > dip + self.pull_up_rise_m)
        kepler = c.kepler | (pulled & (ng1 < self.kepler_load_g))
        descending = pulled & (hdot1 < 0.0) & (ng1 >= self.kepler_load_g)
        by_speed = self._by_speed()
        switch = kepler & descending & ~by_speed
        # a reference switching on speed is flown from its switch speed, Kepler arc or not
        on_speed = pulled & (speed1 <= self.reference.switch_velocity_mps)
        crest = ~kepler & self._skip_switch(pulled, hdot1, ng1, speed1)
        second = c.second | jnp.where(by_speed, on_speed, crest)
        chute = alt1 < self.chute_altitude_m
        skip = alt1 > self.skip_out_altitude_m
        dive = ~(ng1 <= self.predictor_dive_load_g)  # (a NaN state too)
        kind = jnp.where(switch, 0, jnp.where(chute, 1, jnp.where(skip, 2, -1)))
        kind = jnp.where(dive, 4, kind).astype(jnp.int32)
        speed_bank = speed1
        if self.predictor_bank == "midpoint":  # the speed half-way through the next step
            dt_next = self.predictor_dt_s
            if self.predictor_coast_dt_s != dt_next:
                dt_next = jnp.where(
                    ng1 < self.predictor_coast_load_g, self.predictor_coast_dt_s, dt_next
                )
            speed_bank = speed1 + (0.5 * dt_next / dt) * (speed1 - c.now.speed_mps)
        cos_b1 = jnp.cos(self._bank(second, sigma_0, v_0, speed_bank))
        if self.predictor_apogee == "blend":
            cos_b1 = self._apogee_blend(
                cos_b1, c.now, dt, alt1, hdot1, ng1, speed1, speed_bank, dip, pulled, kepler, second
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
        )

    def _apogee_blend(
        self,
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
        dt = self.predictor_dt_s
        if self.predictor_coast_dt_s != dt:
            dt = jnp.where(ng1 < self.predictor_coast_load_g, self.predictor_coast_dt_s, dt)
        # time to the switch: to the reference's switch speed, or to the apogee
        decel = (now.speed_mps - speed1) / dt_taken
        tau_speed = (speed1 - self.reference.switch_velocity_mps) / jnp.where(
            decel > 0.0, decel, 1.0
        )
        fall = (now.hdot_mps - hdot1) / dt_taken  # -dHdot/dt over the step just taken
        tau_apogee = hdot1 / jnp.where(fall > 0.0, fall, 1.0)
        by_speed = self._by_speed()
        tau = jnp.where(by_speed, tau_speed, tau_apogee)
        coming = jnp.where(
            by_speed,
            (tau_speed > 0.0) & (decel > 0.0),
            (hdot1 > 0.0) & (fall > 0.0) & self._apogee_gate(speed1),
        )
        at_switch = pulled | (alt1 + 0.5 * hdot1 * tau > dip + self.pull_up_rise_m)
        no_kepler = ~kepler & (ng1 >= self.kepler_load_g)
        blend = ~second & (by_speed | no_kepler) & coming & (tau < dt) & at_switch
        f = jnp.clip(tau / dt, 0.0, 1.0)
        cos_ref = jnp.cos(self.reference.bank_at(speed_bank))
        return jnp.where(blend, f * cos_b1 + (1.0 - f) * cos_ref, cos_b1)

    def _end_point(self, c: _PredictorState):
        """State and time where a finished prediction ends, inside its last step (a prediction
        that took no step: its start). The altitude of the end point is the chute's, or for
        the switch point that where the load crosses ``kepler_load_g`` on a log-linear
        interpolation in altitude (the load grows nearly exponentially with depth); the time
        fraction of that altitude is found on the cubic Hermite interpolant of the altitude,
        and the position there on that of the position (from the velocities at both ends),
        the velocity linearly. A linear interpolation of the load in time misplaces the switch
        point by kilometres at 16 s steps, in wiggles of the range error along sigma_0 that
        the corrector's 5 km tolerance does not absorb."""
        dt = self.predictor_dt_s if self.predictor_coast_dt_s == self.predictor_dt_s else c.dt
        a, b = c.before, c.now
        log_a, log_b = jnp.log(jnp.maximum(a.ng, 1e-30)), jnp.log(jnp.maximum(b.ng, 1e-30))
        w = jnp.clip(
            (jnp.log(self.kepler_load_g) - log_a) / jnp.where(log_b != log_a, log_b - log_a, 1.0),
            0.0,
            1.0,
        )
        level = jnp.where(
            c.kind == 0, a.altitude_m + w * (b.altitude_m - a.altitude_m), self.chute_altitude_m
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

    def _prediction(self, c: _PredictorState, y, t, model, target_fixed) -> Prediction:
        """Range error and crossrange of a finished prediction started at ``(y, t)``."""
        earth = model.earth
        y_end, t_end = self._end_point(c)
        kind = jnp.where(c.kind < 0, 2, c.kind)  # out of steps: treat as a skip-out
        r_e = earth.equatorial_radius_m
        # Signed along-track position of the end point relative to the target, on the great
        # circle from here to the target (> 0 beyond it): a long skip that passes over the
        # target must count as an overshoot, which an unsigned distance would not.
        here = unit(to_earth_fixed(y.r, t, earth.rotation_rate))
        end = unit(to_earth_fixed(y_end.r, t_end, earth.rotation_rate))
        beyond = r_e * along_cross_track(end, here, target_fixed)[0]
        s2 = self.reference.second_entry_range(flight_variables(y_end, earth))
        overshoot = 2.0 * self.reference.range_to_go_m[0] + 1.0e7
        landed = (kind == 1) | (kind == 4)
        miss = jnp.where(kind == 0, s2 + beyond, jnp.where(landed, beyond, overshoot))
        target = to_inertial(target_fixed, t_end, earth.rotation_rate)
        v_rel = y_end.v - jnp.cross(earth.angular_velocity(), y_end.r)
        chi = r_e * crossrange_to_target(y_end.r, v_rel, target)
        return Prediction(miss, chi, kind, c.k)

    def correct(
        self,
        y,
        t,
        pulled_up,
        sigma_prev,
        model,
        target_fixed,
        enabled,
        slope=None,
        dip_altitude_m=None,
    ):
        """Bounded regula falsi on sigma_0 (seed 003 eqs. 11-15), at most
        1 + n_bracket + n_iter predictions.

        Warm-started at the previous solution; with ``corrector_start = "secant"`` and the
        previous cycle's ``slope`` (m/rad), a miss of the warm start is followed by the secant
        step on that slope instead of the Δσ step of eq. 15. The result's ``aux`` is the
        predicted crossrange at the switch point of the solution, its ``cost`` the number of
        predictor RK4 steps taken by all predictions of the cycle, its ``slope`` this
        cycle's.

        The predictions of the whole cycle are one loop over predictor steps, in rounds of
        ``ROUND_STEPS``: after each round, a run whose prediction has ended gives its range
        error to the root finder (the :class:`~gnc_jax.root_finding.RegulaFalsi` machine) and
        starts the prediction it proposes next. Under ``vmap`` the loop runs until the run
        with the most predictor steps in the cycle is done; with a loop per prediction slot
        instead, every slot runs as long as its slowest run, which at 16 s steps costs a
        256-run chunk's corrector 7 % more. The solve is the same either way."""

        secant = self.corrector_start == "secant"
        solver = regula_falsi(
            self.bracket_step_rad,
            self.bank_min_rad,
            self.bank_max_rad,
            self.range_tolerance_m,
            self.n_bracket,
            self.n_iter,
            illinois=True,
            decreasing=True,
            enabled=enabled,
            slope=slope if secant else None,
            anderson_bjorck=secant,
        )
        origin = self._origin(y, t, pulled_up, model, dip_altitude_m)
        z = jnp.zeros(())
        s = solver.init(sigma_prev, z, z)
        x, active = solver.propose(s)

        def steps(c, sigma_0):
            """Up to ROUND_STEPS steps of the prediction."""
            c, _ = jax.lax.while_loop(
                lambda cj: self._integrating(cj[0]) & (cj[1] < ROUND_STEPS),
                lambda cj: (
                    self._predictor_step(cj[0], sigma_0, origin.speed_mps, model),
                    cj[1] + 1,
                ),
                (c, jnp.asarray(0, jnp.int32)),
            )
            return c

        def round_(carry):
            s, x, c = carry
            c = steps(c, x)
            end = ~self._integrating(c)
            p = self._prediction(c, y, t, model, target_fixed)
            s = _where(end, solver.absorb(s, x, p.miss_m, p.crossrange_m, p.steps.astype(float)), s)
            x_next, active = solver.propose(s)
            c_next = self._predictor_start(origin, x_next, active, model)
            return s, jnp.where(end, x_next, x), _where(end, c_next, c)

        c = self._predictor_start(origin, x, active, model)
        s, _, _ = jax.lax.while_loop(lambda sxc: ~solver.done(sxc[0]), round_, (s, x, c))
        return solver.result(s)

    # ---- reference tracking (seed 003 §2.2, eqs. 6-7, 16-17) ----
    def switch_compensation(self, fv: FlightVariables, range_to_go_m) -> Scalar:
        """Bank offset (rad) at the switch point (eqs. 16-17, signs made consistent): the
        offset that makes the expanded second-entry range equal the actual range to go."""
        s2 = self.reference.second_entry_range(fv)
        return (range_to_go_m - s2) / self.reference.d_range_d_bank

    def feedback_gains(self, speed):
        """Gain vector K(v) of eq. 7 on (ΔN_gx, ΔḢ, ΔS, ΔṠ), per g, s/m, 1/m, s/m.

        The gains are scheduled with speed from the reference's own range sensitivities (as
        Apollo's final phase does): the range the current deviations will add,
        ΔR = dR/dN ΔN_gx + dR/dḢ ΔḢ - t_go ΔṠ, is compared with the range to go deviation ΔS,
        and the difference is removed with cos sigma through dR/dcos. The four leaves
        ``k_range`` (overall gain on ΔS - ΔR) and ``k_drag_load``, ``k_hdot``, ``k_range_rate``
        (weights of the predicted-range terms) are dimensionless multipliers (1 = nominal).
        """
        f_drag, f_hdot, f_cos, t_go = self.reference.sensitivities(speed)
        f_cos = jnp.maximum(f_cos, 1.0e3)  # no authority left near the chute: bounded gains
        k = self.k_range / f_cos
        return jnp.stack(
            [
                -k * self.k_drag_load * f_drag,
                -k * self.k_hdot * f_hdot,
                k,
                k * self.k_range_rate * t_go,
            ]
        )

    def track(self, speed, drag_load, hdot, range_to_go, range_rate, ld_ratio, bank_offset):
        """Commanded bank magnitude (rad) of the second entry (eqs. 6-7).

        ``ld_ratio``: measured L/D over the reference (L/D)_0."""
        ref_bank, ref_s, ref_hdot, ref_ngx, ref_sdot = self.reference.lookup(speed)
        delta = jnp.stack(
            [drag_load - ref_ngx, hdot - ref_hdot, range_to_go - ref_s, range_rate - ref_sdot]
        )
        k_delta = jnp.dot(self.feedback_gains(speed), delta)
        cos_cmd = (jnp.cos(ref_bank + bank_offset) + k_delta) / ld_ratio
        # keep a minimum bank so that the lateral channel never loses all its authority
        lim = jnp.cos(self.track_bank_min_rad)
        return jnp.arccos(jnp.clip(cos_cmd, -lim, lim))

    def funnel_m(self, speed):
        return self.funnel_base_m + self.funnel_quadratic_s2_m * speed**2

    def hold_bank_rad(self, ctx: EntryGuidanceContext) -> Scalar:
        """Bank magnitude of the hold phase (see ``hold_bank``), rad."""
        if self.hold_bank == "designed":
            return self.reference.first_entry_bank_rad
        return ctx.hold_bank_rad

    # ---- the guidance-law protocol ----
    def init(self, nav: EntryNav, ctx: EntryGuidanceContext) -> SkipEntryState:
        """Hold phase at t = 0, with the nominal first-entry bank as the corrector's guess."""
        z = jnp.zeros(())
        zi = jnp.zeros((), int)
        log = EntryGuidanceLog(
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
        return SkipEntryState(
            phase=zi,
            pulled_up=jnp.asarray(False),
            dip_altitude_m=jnp.asarray(jnp.inf),
            sigma_0=self.reference.first_entry_bank_rad,
            sign=jnp.ones(()),
            bank_mag=self.hold_bank_rad(ctx),
            bank_offset=z,
            drag_ratio=jnp.ones(()),
            lift_ratio=jnp.ones(()),
            last_status=zi,
            predicted_crossrange=z,
            corrector_slope=jnp.full((), jnp.nan),
            plan_speed=jnp.full((), jnp.nan),
            step=zi,
            log=log,
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
        drag_ratio, lift_ratio = self.filter_ratios(state, nav, ng, ctx)
        model = EntryModel(ctx.model.vehicle, earth, ctx.model.atmosphere, drag_ratio, lift_ratio)
        target = to_inertial(ctx.target_fixed, t, earth.rotation_rate)
        v_rel = y.v - jnp.cross(earth.angular_velocity(), y.r)
        to_go = earth.equatorial_radius_m * along_track_to_go(y.r, v_rel, target)
        live = ~(fv.altitude_m < self.chute_altitude_m)

        phase, pulled, dip, events = self._phase_events(state, fv, ng, live)
        bank_offset = jnp.where(
            events.to_track, self.switch_compensation(fv, to_go), state.bank_offset
        )
        res, did_pc = self._corrector_cycle(
            state, y, t, fv.speed_mps, ctx, model, pulled, live & (phase == 1)
        )
        sigma_0 = jnp.where(did_pc, res.x, state.sigma_0)
        chi_switch = jnp.where(did_pc, res.aux, state.predicted_crossrange)

        range_rate = earth.equatorial_radius_m * range_rate_to_target(y.r, v_rel, target)
        c_l0, c_d0 = ctx.model.vehicle.c_l, ctx.model.vehicle.c_d
        ld = nav.lift_mps2 / jnp.maximum(nav.drag_mps2, 1e-12)
        track_mag = self.track(
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
            self.hold_bank_rad(ctx),
            jnp.where(
                phase == 1,
                self.profile(sigma_0, fv.speed_mps, fv.speed_mps),
                jnp.where(phase == 2, state.bank_mag, track_mag),
            ),
        )
        chi_now = earth.equatorial_radius_m * crossrange_to_target(y.r, v_rel, target)
        sign, reverse = self._bank_sign(state, phase, fv, chi_switch, chi_now, live, pulled, ng)

        log = self._log(state, y, t, ctx, fv, phase, events, res, did_pc, reverse, live)
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

    def filter_ratios(self, state: SkipEntryState, nav: EntryNav, ng, ctx: EntryGuidanceContext):
        """Ratios of the measured drag and lift to those of the on-board model at the
        navigated state, first-order filtered (gain ``ctx.ratio_filter_gain`` per step) while
        the sensed load ``ng`` exceeds 0.05 g; the predictor scales its model by them."""
        m = ctx.model
        drag_model, lift_model = drag_and_lift(nav.y, m.vehicle, m.earth, m.atmosphere)
        sensing = ng > 0.05
        k = ctx.ratio_filter_gain
        drag_ratio = jnp.where(
            sensing,
            state.drag_ratio
            + k * (nav.drag_mps2 / jnp.maximum(drag_model, 1e-12) - state.drag_ratio),
            state.drag_ratio,
        )
        lift_ratio = jnp.where(
            sensing,
            state.lift_ratio
            + k * (nav.lift_mps2 / jnp.maximum(lift_model, 1e-12) - state.lift_ratio),
            state.lift_ratio,
        )
        return drag_ratio, lift_ratio

    def _phase_events(self, state: SkipEntryState, fv: FlightVariables, ng, live):
        """Phase of this step (hard logic, seed 003 Fig. 1), the pull-up flag, the dip's
        altitude and the events."""
        phase = state.phase
        start = live & (phase == 0) & (ng > self.ng0_g)
        phase = jnp.where(start, 1, phase)
        dip = jnp.where(
            (phase >= 1) & ~state.pulled_up,
            jnp.minimum(state.dip_altitude_m, fv.altitude_m),
            state.dip_altitude_m,
        )
        pulled = state.pulled_up | ((phase >= 1) & (fv.altitude_m > dip + self.pull_up_rise_m))
        to_kepler = live & (phase == 1) & pulled & (fv.hdot_mps > 0.0) & (ng < self.kepler_load_g)
        phase = jnp.where(to_kepler, 2, phase)
        kepler_end = (phase == 2) & pulled & (fv.hdot_mps < 0.0) & (ng >= self.kepler_load_g)
        # (a reference switching on speed: a Kepler arc that ends faster than its switch
        # speed goes back to the first entry, as the predictor flies it)
        slow = ~self._by_speed() | (fv.speed_mps <= self.reference.switch_velocity_mps)
        to_track = live & (
            (kepler_end & slow)
            | ((phase == 1) & self._skip_switch(pulled, fv.hdot_mps, ng, fv.speed_mps))
        )
        phase = jnp.where(live & kepler_end & ~slow, 1, phase)
        phase = jnp.where(to_track, 3, phase)
        return phase, pulled, dip, _PhaseEvents(start, to_kepler, to_track)

    def warm_start(self, state: SkipEntryState, speed):
        """The corrector's first guess at ``speed``: with ``corrector_start = "secant"`` the
        bank the last solution's profile planned for this speed (the root it would have
        if the flight went as planned), else the last solution sigma_0 itself (seed 003)."""
        if self.corrector_start != "secant":
            return state.sigma_0
        planned = self.profile(state.sigma_0, state.plan_speed, speed)
        return jnp.where(jnp.isnan(state.plan_speed), state.sigma_0, planned)

    def _corrector_cycle(self, state: SkipEntryState, y, t, speed, ctx, model, pulled, active):
        """The corrector on a predictor-corrector step (every ``pc_every`` control steps),
        else the previous solution. Returns the result and whether it is a new solution: only
        an ``active`` run (in phase 1) does any work."""

        def pc(_):
            res = self.correct(
                y,
                t,
                pulled,
                self.warm_start(state, speed),
                model,
                ctx.target_fixed,
                active,
                state.corrector_slope,
                state.dip_altitude_m,
            )
            return res._replace(slope=jnp.asarray(res.slope, dtype=float))

        def no_pc(_):
            z = jnp.zeros((), int)
            return RegulaFalsiResult(
                x=state.sigma_0,
                f_x=jnp.zeros(()),
                converged=jnp.asarray(True),
                n_evals_early_exit=z,
                n_evals_total=z,
                status=z,
                aux=state.predicted_crossrange,
                cost=jnp.zeros(()),
                slope=state.corrector_slope,
            )

        if ctx.cycle_start is None:
            is_pc_step = (state.step % ctx.pc_every) == 0
        else:
            is_pc_step = ctx.cycle_start
        active = active & is_pc_step  # (should the cond be batched, an idle step predicts nothing)
        res = jax.lax.cond(is_pc_step, pc, no_pc, None)
        return res, active

    def switch_threshold_m(self, pulled, ng):
        """First-entry reversal threshold on the predicted switch-point crossrange, m:
        ``switch_crossrange_m``, narrowing after the pull-up linearly with the load from
        ``switch_narrow_load_g`` down to ``switch_crossrange_final_m`` at the Kepler load,
        where the first entry's last reversal is made."""
        w = jnp.clip(
            (ng - self.kepler_load_g)
            / jnp.maximum(self.switch_narrow_load_g - self.kepler_load_g, 1e-6),
            0.0,
            1.0,
        )
        narrowed = self.switch_crossrange_final_m + w * (
            self.switch_crossrange_m - self.switch_crossrange_final_m
        )
        return jnp.where(
            pulled, jnp.minimum(narrowed, self.switch_crossrange_m), self.switch_crossrange_m
        )

    def _bank_sign(self, state: SkipEntryState, phase, fv, chi_switch, chi_now, live, pulled, ng):
        """Sign of the bank and whether it reverses this step.

        The bank reverses when the crossrange leaves the funnel (phases 1 and 3); the first
        entry judges the crossrange predicted at the switch point, which includes the drift of
        the rotating Earth under the Kepler arc, against :meth:`switch_threshold_m`."""
        chi = jnp.where(phase == 1, chi_switch, chi_now)
        want = -jnp.sign(chi)  # negative bank turns left, towards a target on the left
        threshold = jnp.where(
            phase == 1, self.switch_threshold_m(pulled, ng), self.funnel_m(fv.speed_mps)
        )
        outside = (jnp.abs(chi) > threshold) & ((phase == 1) | (phase == 3))
        reverse = live & outside & (want != state.sign)
        return jnp.where(reverse, want, state.sign), reverse

    def _log(self, state: SkipEntryState, y, t, ctx, fv, phase, events, res, did_pc, reverse, live):
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
            skipped_out=log.skipped_out | (live & (fv.altitude_m > self.skip_out_altitude_m)),
            entry_r_m=log.entry_r_m,
            step_predictions=evals,
            step_miss_m=jnp.where(did_pc, res.f_x, 0.0),
        )
