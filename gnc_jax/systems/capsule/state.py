"""The state of a capsule run, by kind, and what it returns.

A run's carry is a :class:`~gnc_jax.systems.loop.LoopState` (:data:`CapsuleLoopState`): the true
flight (:class:`CapsuleTruth`), no estimate (navigation is perfect), the law's state, the bank
actuator's state (:class:`~gnc_jax.dynamics.entry.BankActuatorState`) and what the outcome
accumulates (:class:`CapsuleTally`); a run's fixed draws are a :class:`CapsuleDraws`. A run
returns a :class:`CapsuleOutcome` and, when recorded, a :class:`Trace` per control step.
"""

from typing import NamedTuple

from ..._types import Array, Float, Scalar, Vector3
from ...dynamics.entry import EntryArgs, EntryState, EntryStateXYZ
from ..loop import LoopState


class CapsuleOutcome(NamedTuple):
    status: Array
    downrange_err_km: Scalar  # > 0 overshoot
    crossrange_err_km: Scalar  # > 0 left of the entry -> target track
    load_peak_g: Scalar
    heat_rate_peak_kw_m2: Scalar
    heat_load_mj_m2: Scalar
    skip_apogee_km: Scalar
    switch_speed_mps: Scalar
    switch_altitude_km: Scalar
    switch_hdot_mps: Scalar
    switch_range_km: Scalar  # ground range flown from the entry point to the switch point
    bank_offset_deg: Scalar  # switch-point compensation (eqs. 16-17)
    predictions: Array  # predictions an early-exit corrector would have made (whole flight)
    cycle_predictions_max: Array
    pc_cycles: Array
    corrector_failures: Array
    reversals: Array
    predictor_steps: Scalar  # RK4 steps of all predictions (4 right-hand sides each)
    t_guidance_s: Scalar
    t_kepler_s: Scalar
    t_switch_s: Scalar
    t_chute_s: Scalar
    dispersion: Float[Array, "10"]  # the draws, in the order of CapsuleDispersions


class Trace(NamedTuple):
    t_s: Scalar
    altitude_m: Scalar
    speed_mps: Scalar
    range_flown_m: Scalar
    bank_cmd_rad: Scalar
    bank_rad: Scalar
    load_g: Scalar
    phase: Array
    sigma_0_rad: Scalar  # corrector solution
    predicted_miss_m: Scalar  # corrector residual at that solution (0 outside a PC cycle)
    corrector_evals: Array  # predictions an early-exit corrector would make this step
    r_m: Vector3  # ECI state
    v_mps: Vector3
    pulled_up: Array
    drag_ratio: Scalar
    lift_ratio: Scalar


class CapsuleTruth(NamedTuple):
    """The true flight, advanced one RK4 step at a time by the simulation: the state as
    components (:class:`EntryStateXYZ`) with the density at it, which the next step's first
    right-hand side reuses, the time, and whether the chute altitude has been crossed (a
    finished flight is frozen)."""

    y: EntryStateXYZ
    density: Scalar  # truth density at y, kg/m^3
    t: Scalar
    done: Array


class CapsuleTally(NamedTuple):
    """What the outcome accumulates along the flight: loads and heating, and the step that
    crossed the chute altitude (its start state, time and bank), from which the simulation
    locates the crossing after the loop."""

    cross_y: EntryStateXYZ  # state at the start of the crossing step
    cross_t: Scalar
    cross_bank: Scalar  # bank flown over the crossing step
    heat_load: Scalar  # J/m^2
    heat_peak: Scalar  # W/m^2
    load_peak: Scalar  # g


class CapsuleDraws(NamedTuple):
    """What a run draws once and never changes: the dispersed entry state, the truth models
    (dispersed vehicle and atmosphere) and the standard-normal draws of the outcome."""

    y0: EntryState
    truth: EntryArgs
    dispersion: Float[Array, "10"]


CapsuleLoopState = LoopState
"""The capsule's :class:`~gnc_jax.systems.loop.LoopState`: ``truth`` a :class:`CapsuleTruth`,
``estimate`` ``()`` (perfect navigation: the law's filtered drag and lift ratios calibrate its
own predictor's model and live in its state), ``law`` the law's state, ``actuator`` the
:class:`~gnc_jax.dynamics.entry.BankActuatorState` (the bank actually flown and its roll
rate), ``tally`` a :class:`CapsuleTally`."""
