"""The parameters of the skip-entry law (seed 003): every gain, threshold and option of
``[guidance.skip_entry]``, declared once with :func:`~gnc_jax.params.param`, and their
cross-field checks.

:class:`SkipEntryParameters` is the abstract base of
:class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance`, which adds the law's
``from_config``, ``init`` and ``step``.
"""

import math

import equinox as eqx

from ..._types import Array, Float, Scalar
from ...params import param, si_value
from ...schema import ScenarioError
from ..schedule import check_schedules
from .base import AbstractEntryGuidance
from .reference import ReferenceTrajectory

__all__ = ["TRACKING_GAINS", "SkipEntryParameters"]

DEG = math.pi / 180.0  # math.radians(x) is x * DEG to the last bit


TRACKING_GAINS = ("k_drag_load", "k_hdot", "k_range", "k_range_rate")


def _speed_schedule(gain: str):
    return param(
        [],
        lo=0.0,
        hi=100.0,
        doc=f"{gain} at the speeds schedule_speed_kmps, linear between; [] = the constant {gain}",
        tunable=True,
    )


class SkipEntryParameters(AbstractEntryGuidance):
    """The declared parameters of the combined predictor-corrector / reference-trajectory law
    of seed 003 (abstract: the law is
    :class:`~gnc_jax.guidance.entry.skip_entry.SkipEntryGuidance`).

    Gains and thresholds are array leaves (differentiable); loop sizes are static.

    Attributes:
        reference: the designed second-entry reference.
        k_drag_load, k_hdot, k_range, k_range_rate: dimensionless multipliers of the
            speed-scheduled gain vector of eq. 7 (see
            :func:`~gnc_jax.guidance.entry.tracking.feedback_gains`).
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
        load_limit_g: the capsule's load limit (``simulation.load_limit_g``), g: the load
            relief keeps the sensed load within ``load_relief_fraction`` of it, and a
            prediction loaded beyond ``predictor_load_fraction`` of it is a dive.
        direct: whether the law flies its direct-entry mode (static), resolved by the capsule
            system from ``entry_mode`` and handed over in the mission.
    """

    reference: ReferenceTrajectory
    chute_altitude_m: Scalar
    load_limit_g: Scalar
    # the mode flown, resolved by the capsule system from entry_mode ("auto": from the reach)
    direct: bool = eqx.field(static=True, default=False)
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
    k_drag_load_schedule: Float[Array, " n"] = _speed_schedule("k_drag_load")
    k_hdot_schedule: Float[Array, " n"] = _speed_schedule("k_hdot")
    k_range_schedule: Float[Array, " n"] = _speed_schedule("k_range")
    k_range_rate_schedule: Float[Array, " n"] = _speed_schedule("k_range_rate")
    schedule_speed_mps: Float[Array, " n"] = param(
        [],
        toml="schedule_speed_kmps",
        scale=1e3,
        lo=0.0,
        units="km/s",
        doc="speed breakpoints of the tracking gains' schedules, increasing",
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
    direct_range_tolerance_m: Scalar = param(
        1.0,
        toml="direct_range_tolerance_km",
        scale=1e3,
        lo=0.001,
        hi=1000.0,
        units="km",
        doc="corrector tolerance on the predicted range error in the direct-entry mode, which "
        "has no tracked second entry to remove what the corrector leaves: the packaged capsule "
        "at -5.9 deg / 2000 km, 8 runs, lands within 4.9 km at 5 km and 1.0 km at 1 km",
    )
    direct_final_speed_mps: Scalar = param(
        1000.0,
        lo=0.0,
        hi=1e4,
        units="m/s",
        doc="direct-entry mode: below this Earth-relative speed the corrector stops and the "
        "last solution is flown down to the chute. Near the chute the bank no longer moves the "
        "predicted range by the corrector's tolerance, so its last cycles failed on runs that "
        "landed within 1 km (2 of 8 at -5.9 deg / 1600 km)",
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
    predictor_load_fraction: Scalar = param(
        0.9,
        lo=0.0,
        lo_open=True,
        hi=100.0,
        doc="in a skip, a prediction whose load exceeds this fraction of the capsule's load "
        "limit (simulation.load_limit_g) is a dive too, as beyond predictor_dive_load_g, so "
        "the corrector plans no profile that loads the capsule beyond it: a margin for the "
        "dispersions between a prediction and the flight. Flying its predictions up to the "
        "20 g guard, a steep skip's corrector banked into loads it could not fly: at -7.1 deg "
        "all 200 runs to 2500 km and 93 to 4000 km read overload, 13 and 10 with it. A direct "
        "entry keeps the guard alone: at the short end of its reach (designed within 90 % of "
        "the limit) the margin turned overloads into more misses (second vehicle, -5.7 deg / "
        "2500 km: 15 overload -> 47 missed). A fraction of 2 or more leaves the guard alone "
        "for the packaged 10 g capsule",
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
    predictor_horizon: str = param(
        "chute_crossrange",
        choices=("switch", "chute_crossrange", "chute"),
        doc="where a prediction that reaches the switch point ends: there, adding the second "
        "entry's range by the first-order expansion of seed 003 eq. 10 about the reference's "
        "switch state and judging the crossrange there ('switch', the paper's); or, for a "
        "prediction started after the pull-up, it flies on with the second entry's bank "
        "(second_entry_bank) down to the chute, for the crossrange only ('chute_crossrange': "
        "the first entry's last reversals then see the drift the rotating Earth adds under "
        "the second entry, about 20 km on the paper's nominal) or for the crossrange and the "
        "range ('chute'). Before the pull-up every horizon ends at the switch point: a "
        "chute crossrange judged there jumps with the prediction's kind near the corridor's "
        "edge and made the bank reverse every few seconds (L/D 0.40, -5.2 deg / 8000 km: 5 "
        "skip-outs in 200 runs against 1). Flying on takes 1.36 times the predictor's steps "
        "on the paper scenario (its 1000-run study 15-18 % more time); see the design "
        "decisions",
    )
    second_entry_bank: str = param(
        "tracked",
        choices=("reference", "tracked"),
        doc="bank a prediction flies in a second entry it flies (a skip without a Kepler "
        "phase, or flown on to the chute: predictor_horizon): the reference's "
        "('reference') or the reference's vertical lift as the tracking commands it "
        "('tracked': cos sigma divided by the measured L/D over the reference's, eq. 6 "
        "without its feedback, at least track_bank_min_deg), so that a run whose L/D is "
        "off its model predicts the second entry its tracking will fly",
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
    entry_mode: str = param(
        "auto",
        choices=("auto", "skip", "direct"),
        doc="'skip': the combined law of seed 003 (a first entry, a Kepler phase or an apogee, "
        "a tracked second entry); 'direct': the same predictor-corrector with a constant "
        "predicted bank down to the chute, no Kepler phase and no second entry, bank reversals "
        "inside the crossrange funnel (targets short of the skip's reach); 'auto': 'direct' "
        "where the target lies inside the nominal vehicle's direct reach (constant-bank "
        "landings without a skip: gnc_jax.guidance.entry.direct), else 'skip'",
    )
    load_relief: str = param(
        "direct",
        choices=("direct", "off"),
        doc="load relief of the direct entry (not in seed 003): after the first pull-up, while "
        "the sensed load extrapolated load_relief_lead_s ahead exceeds load_relief_fraction of "
        "the capsule's load limit (simulation.load_limit_g), the law flies full lift up and its "
        "predictor flies the same rule, so that the corrector plans the range the relief costs "
        "('direct'); or none ('off', seed 003's law). A direct entry near the far end of its "
        "reach lofts and dives into a second dip: at -5.9 deg / 3000 km 26 of 200 runs peaked "
        "there at 10.2-11.4 g without it, none above 8.9 g with it. Not in the first dip, where "
        "the corrector must lose energy (at 1700 km relieving there turned 15 overloads into "
        "102 misses and non-convergences), and not in a skip: its predictions' second entries "
        "relieved, the shallow -5.3 deg / 4000 km cell fell from 99.0 to 73.0 % ok",
    )
    load_relief_fraction: Scalar = param(
        0.95,
        lo=0.0,
        lo_open=True,
        hi=1.0,
        doc="the load relief's threshold as a fraction of simulation.load_limit_g",
    )
    load_relief_lead_s: Scalar = param(
        10.0,
        lo=0.0,
        hi=60.0,
        units="s",
        doc="how far ahead the load relief extrapolates the sensed load: by the on-board "
        "atmosphere's density ratio between the altitude now and that reached in this time at "
        "the present sink rate (0: the sensed load alone, which reacts too late: the load "
        "climbs by a third every 10 s in a steep second dip)",
    )
    n_bracket: int = param(6, lo=1, hi=100, doc="bracketing steps of the corrector")
    n_iter: int = param(6, lo=1, hi=100, doc="regula-falsi iterations of the corrector")

    schedules = {f"{g}_schedule": g for g in TRACKING_GAINS}  # schedule -> the gain it replaces
    # fields read only by the tracking phase (eqs. 6-7), which no run leaves and which follows
    # the first entry, the only phase that runs the corrector: none reaches its solutions
    acts_after_corrector = frozenset(TRACKING_GAINS) | frozenset(schedules)
    schedule_breakpoints = "schedule_speed_kmps"

    @classmethod
    def check(cls, section, config):
        check_schedules(section, cls.schedule_breakpoints, cls.schedules, "guidance.skip_entry")
        if section["bank_min_deg"] >= section["bank_max_deg"]:
            raise ScenarioError(
                f"guidance.skip_entry.bank_min_deg: {section['bank_min_deg']:g} deg; allowed: "
                f"below guidance.skip_entry.bank_max_deg = {section['bank_max_deg']:g} deg"
            )
        if section["predictor_coast_load_g"] >= section["kepler_load_g"]:
            # the switch point (the load rising through kepler_load_g) is located in a step
            # of predictor_dt_s only if the coast steps stop below it
            raise ScenarioError(
                "guidance.skip_entry.predictor_coast_load_g: "
                f"{section['predictor_coast_load_g']:g} g; allowed: below "
                f"guidance.skip_entry.kepler_load_g = {section['kepler_load_g']:g} g"
            )

    @classmethod
    def check_entry(cls, section, entry_altitude_m):
        skip_out_m = float(si_value(cls, "skip_out_altitude_m", section["skip_out_altitude_km"]))
        if skip_out_m <= entry_altitude_m:
            # the flight would count as a skip-out from its first step
            raise ScenarioError(
                f"guidance.skip_entry.skip_out_altitude_km: {section['skip_out_altitude_km']:g}"
                f" km; allowed: above the entry interface ({entry_altitude_m:g} m)"
            )
