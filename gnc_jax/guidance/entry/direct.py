"""The direct-entry mode of the capsule law: its reach, its nominal design and its reference.

Short of the skip's reach, the capsule lands without a Kepler phase: the vehicle stays in the
atmosphere after the first entry, as Apollo's guidance flew whenever the range did not need a
skip. The law's direct mode (``guidance.skip_entry.entry_mode``) keeps the same numerical
predictor-corrector (seed 003 §3.1, eqs. 11-15) but predicts straight down to the chute with a
constant bank sigma_0 and never switches to reference tracking; the bank reversals keep the
crossrange inside the speed-scheduled funnel of the second entry.

The direct reach of a vehicle, entry and target is the interval of chute ranges of the nominal
flown with a constant bank in ``DIRECT_BANK_BOUNDS_RAD`` that lands without climbing above
``DIRECT_APOGEE_M`` after its first pull-up (:func:`direct_reach`). The design
(:func:`design_direct`) is the constant bank whose nominal lands on the target, a bounded
regula-falsi solve inside the scanned pair of banks that brackets it; its
:class:`~gnc_jax.guidance.entry.reference.ReferenceTrajectory` (:func:`direct_reference`)
carries that bank as the hold bank and the corrector's first guess, and no second entry.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ...root_finding import bounded_regula_falsi
from ...schema import ScenarioError
from .nominal import (
    LANDS_WITHOUT_SKIP,
    RANGE_TOLERANCE_M,
    SIGMA_1_BOUNDS_RAD,
    V_SWITCH_INIT_MPS,
    NominalProblem,
    fate_of,
    fly_nominal,
    range_error_m,
)
from .reach import conditions
from .reference import ReferenceTrajectory

# The constant banks a direct design may fly: the first-entry bounds, which leave the
# corrector 15 deg of bank either side of full lift up and down for the dispersions.
DIRECT_BANK_BOUNDS_RAD = SIGMA_1_BOUNDS_RAD
DIRECT_SCAN_STEP_RAD = math.radians(0.5)
# A nominal that climbs higher than this after its first pull-up leaves the sensible
# atmosphere (a 7 km/s capsule at beta ~ 350 kg/m^2 senses about 1 g at 65 km and the
# Kepler-phase 0.2 g near 77 km): a skip, not a direct entry. At -5.9 deg the packaged capsule
# lofts to 56 km at a constant 85 deg bank (2112 km), 65 km at 80 deg (2730 km) and 90 km at
# 75 deg (5099 km).
DIRECT_APOGEE_M = 70.0e3


class DirectScan(NamedTuple):
    """The constant-bank nominals of the scan: banks (rad), chute range errors (m, > 0
    beyond the target) and whether each is a direct landing."""

    banks: np.ndarray
    err_m: np.ndarray
    direct: np.ndarray


@jax.jit
def _constant_bank_flights(problem: NominalProblem, banks):
    def one(bank):
        flight = fly_nominal(problem, bank, bank, bank, V_SWITCH_INIT_MPS)
        # a flight that never pulls up has apogee 0; one that skips (phase 2) recorded the
        # apogee of its first pull-up
        lands = flight.done & ((fate_of(flight) == LANDS_WITHOUT_SKIP) | (flight.apogee > 0.0))
        return range_error_m(problem, flight), lands & (flight.apogee < DIRECT_APOGEE_M)

    return jax.vmap(one)(banks)


def scan_direct(problem: NominalProblem) -> DirectScan:
    """The constant-bank nominals every ``DIRECT_SCAN_STEP_RAD`` over ``DIRECT_BANK_BOUNDS_RAD``."""
    lo, hi = DIRECT_BANK_BOUNDS_RAD
    banks = np.append(np.arange(lo, hi, DIRECT_SCAN_STEP_RAD), hi)
    err_m, direct = (np.asarray(x) for x in _constant_bank_flights(problem, jnp.asarray(banks)))
    return DirectScan(banks, err_m, direct)


def direct_reach(scan: DirectScan) -> tuple[float, float] | None:
    """The chute range errors (m) spanned by the scan's direct landings, or None."""
    if not scan.direct.any():
        return None
    e = scan.err_m[scan.direct]
    return float(e.min()), float(e.max())


def _bracket(scan: DirectScan) -> int | None:
    """Index i of the neighbouring direct landings i, i + 1 whose chute range errors change
    sign (the chute range falls with the bank), the one nearest full lift down (the largest
    control margin towards lift up); None when no pair brackets the target."""
    both = scan.direct[:-1] & scan.direct[1:]
    falls = both & (scan.err_m[:-1] >= 0.0) & (scan.err_m[1:] <= 0.0)
    idx = np.flatnonzero(falls)
    return int(idx[-1]) if idx.size else None


@jax.jit
def _solve_direct_bank(problem: NominalProblem, lo, hi, guess):
    def residual(bank):
        return range_error_m(problem, fly_nominal(problem, bank, bank, bank, V_SWITCH_INIT_MPS))

    return bounded_regula_falsi(
        residual, guess, 0.5 * (hi - lo), lo, hi, RANGE_TOLERANCE_M, 4, 30
    ).x


def reach_text(reach_m, entry: dict) -> str:
    if reach_m is None:
        return "no constant bank lands without a skip"
    lo, hi = reach_m
    return f"{entry['range_km'] + lo / 1e3:.0f} .. {entry['range_km'] + hi / 1e3:.0f} km"


def design_direct(problem: NominalProblem, entry: dict, vehicle: dict, scan=None) -> float:
    """The constant bank (rad) whose direct nominal puts the chute on the target. Refuses
    (:class:`ScenarioError`, naming ``entry.range_km``) a target outside the direct reach."""
    scan = scan_direct(problem) if scan is None else scan
    i = _bracket(scan)
    if i is None:
        b_lo, b_hi = (math.degrees(b) for b in DIRECT_BANK_BOUNDS_RAD)
        raise ScenarioError(
            f"entry.range_km: {entry['range_km']:g} km; allowed: "
            f"{reach_text(direct_reach(scan), entry)}, the chute ranges of a direct entry "
            f"(constant banks {b_lo:.0f}..{b_hi:.0f} deg, no climb above "
            f"{DIRECT_APOGEE_M / 1e3:.0f} km; {conditions(entry, vehicle)})"
        )
    lo, hi = scan.banks[i], scan.banks[i + 1]
    e0, e1 = scan.err_m[i], scan.err_m[i + 1]
    guess = lo + (hi - lo) * e0 / (e0 - e1) if e0 != e1 else lo
    return float(_solve_direct_bank(problem, lo, hi, guess))


def direct_reference(problem: NominalProblem, bank: float, range_m: float) -> ReferenceTrajectory:
    """The reference a direct-mode law carries: the designed constant ``bank`` (its hold
    bank and first guess) and the target's range ``range_m`` (the predictor's skip-out
    penalty scales with it); no second entry (its tables are flat, two nodes)."""
    v0 = float(jnp.linalg.norm(problem.entry.v))
    two = jnp.ones(2)
    zero = jnp.zeros(())
    b = jnp.asarray(bank)
    return ReferenceTrajectory(
        velocity_mps=jnp.asarray([v0, 0.0]),
        bank_rad=b * two,
        range_to_go_m=jnp.asarray([range_m, 0.0]),
        hdot_mps=0.0 * two,
        drag_load_g=0.0 * two,
        range_rate_mps=0.0 * two,
        switch_velocity_mps=zero,
        switch_fpa_rad=zero,
        switch_altitude_m=zero,
        switch_time_s=zero,
        second_entry_range_m=zero,
        d_range_d_switch=jnp.zeros(3),
        d_range_d_bank=jnp.ones(()),
        first_entry_bank_rad=b,
        sigma_a_rad=b,
        sigma_b_rad=b,
        v_end_mps=zero,
        range_per_drag_load_m=0.0 * two,
        range_per_hdot_s=0.0 * two,
        range_per_cos_bank_m=jnp.full(2, 1.0e3),
        time_to_go_s=0.0 * two,
    )
