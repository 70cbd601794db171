"""The direct-entry mode of the capsule law: its reach, its nominal design and its reference.

Short of the skip's reach, the capsule lands without a Kepler phase: the vehicle stays in the
atmosphere after the first entry, as Apollo's guidance flew whenever the range did not need a
skip. The law's direct mode (``guidance.skip_entry.entry_mode``) keeps the same numerical
predictor-corrector (seed 003 §3.1, eqs. 11-15) but predicts straight down to the chute with a
constant bank sigma_0 and never switches to reference tracking; the bank reversals keep the
crossrange inside the speed-scheduled funnel of the second entry.

The direct reach of a vehicle, entry and target is the interval of chute ranges of the nominal
flown with a constant bank in ``DIRECT_BANK_BOUNDS_RAD`` that lands without climbing above
``DIRECT_APOGEE_M`` after its first pull-up and with a sensed load within
``DIRECT_LOAD_FRACTION`` of the load limit, the smaller of the capsule's load limit and the
law's prediction limit (:func:`direct_reach`). The design
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
# The law's predictor ends a prediction whose load exceeds its limit (predictor_dive_load_g,
# 20 g) short, as a dive, so its corrector never settles on a steeper bank: at -5.9 deg the
# packaged capsule's constant banks land down to 1144 km at 165 deg with a 45 g peak, but
# the undispersed closed loop flew a 1200 km target 122 km long (the corrector failing in 27
# of 30 cycles). Near the limit part of the predictions already read as dives (at 20 g:
# 1347 km, 2 of 32 cycles failed; -5.3 deg, 2058 km: 26 of 50 and 21 km long); within 90 %
# of it the undispersed closed loop converged in every cycle and landed within 3.6 km at the
# reach's end from -7.1 to -5.3 deg, at 10.5 and 11.5 km/s, 7 and 11 t, and L/D 0.26 to 0.38
# (L/D 0.23 lands 10.6 km long there at -5.9 deg, and up to 27 km long at -5.3 deg).
DIRECT_LOAD_FRACTION = 0.9


class DirectScan(NamedTuple):
    """The constant-bank nominals of the scan: banks (rad), chute range errors (m, > 0
    beyond the target), whether each is a direct landing, and the load limit (g) a direct
    landing kept within."""

    banks: np.ndarray
    err_m: np.ndarray
    direct: np.ndarray
    load_limit_g: float = math.inf


@jax.jit
def _constant_bank_flights(problem: NominalProblem, banks, load_limit_g):
    def one(bank):
        flight = fly_nominal(problem, bank, bank, bank, V_SWITCH_INIT_MPS)
        # a flight that never pulls up has apogee 0; one that skips (phase 2) recorded the
        # apogee of its first pull-up
        lands = flight.done & ((fate_of(flight) == LANDS_WITHOUT_SKIP) | (flight.apogee > 0.0))
        within = (flight.apogee < DIRECT_APOGEE_M) & (flight.peak_load_g <= load_limit_g)
        return range_error_m(problem, flight), lands & within

    return jax.vmap(one)(banks)


def scan_direct(problem: NominalProblem, load_limit_g: float | None = None) -> DirectScan:
    """The constant-bank nominals every ``DIRECT_SCAN_STEP_RAD`` over ``DIRECT_BANK_BOUNDS_RAD``;
    a direct landing's sensed load stays within ``DIRECT_LOAD_FRACTION`` of ``load_limit_g``
    (g; the smaller of the capsule's ``simulation.load_limit_g`` and the law's
    :meth:`~gnc_jax.guidance.entry.base.AbstractEntryGuidance.predicted_load_limit_g`,
    ``None``: no limit)."""
    lo, hi = DIRECT_BANK_BOUNDS_RAD
    banks = np.append(np.arange(lo, hi, DIRECT_SCAN_STEP_RAD), hi)
    limit = math.inf if load_limit_g is None else DIRECT_LOAD_FRACTION * float(load_limit_g)
    err_m, direct = (
        np.asarray(x)
        for x in _constant_bank_flights(problem, jnp.asarray(banks), jnp.asarray(limit))
    )
    return DirectScan(banks, err_m, direct, limit)


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


def reach_text(scan: DirectScan, entry: dict) -> str:
    """The direct reach of ``scan`` as ranges (km) of the scenario's ``entry`` section."""
    reach_m = direct_reach(scan)
    if reach_m is None:
        return "no range"
    lo, hi = reach_m
    return f"{entry['range_km'] + lo / 1e3:.0f} .. {entry['range_km'] + hi / 1e3:.0f} km"


def direct_conditions(scan: DirectScan) -> str:
    """What makes a flight of ``scan`` a direct landing, in words."""
    b_lo, b_hi = (math.degrees(b) for b in DIRECT_BANK_BOUNDS_RAD)
    load = (
        ""
        if math.isinf(scan.load_limit_g)
        else f", loads up to {scan.load_limit_g:.3g} g = {DIRECT_LOAD_FRACTION:.0%} of the "
        "load limit"
    )
    return (
        f"constant banks {b_lo:.0f}..{b_hi:.0f} deg, no climb above "
        f"{DIRECT_APOGEE_M / 1e3:.0f} km{load}"
    )


def design_direct(problem: NominalProblem, entry: dict, vehicle: dict, scan=None) -> float:
    """The constant bank (rad) whose direct nominal puts the chute on the target. Refuses
    (:class:`ScenarioError`, naming ``entry.range_km``) a target outside the direct reach."""
    scan = scan_direct(problem) if scan is None else scan
    i = _bracket(scan)
    if i is None:
        raise ScenarioError(
            f"entry.range_km: {entry['range_km']:g} km; allowed: "
            f"{reach_text(scan, entry)}, the chute ranges of a direct entry "
            f"({direct_conditions(scan)}; {conditions(entry, vehicle)})"
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
