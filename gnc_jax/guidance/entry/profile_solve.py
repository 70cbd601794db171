"""A reference design that meets the range with the second-entry bank (seed 003 §2.2).

The design of :mod:`gnc_jax.guidance.entry.design` puts the chute on the target by solving
for the first-entry bank sigma_1. Near the overshoot boundary that problem is ill-posed: the
banks that skip and land are a window of a few degrees (the packaged capsule at -5.3 deg:
118.1..120.6 deg; L/D 0.40 at -5.2 deg: about 112..113.5 deg), below it the capsule skips
out, above it lands without a skip, and inside it the chute range is not monotone in sigma_1
(U-shaped; L/D 0.27 at -5.6 deg: 3320 km at best with the 60 deg profile, for a 3000 km
target). The second-entry bank, held constant, moves the chute range monotonically (more bank,
less lift, shorter) by thousands of kilometres there (-5.3 deg, sigma_1 119.5 deg: 5979 km at
45 deg, 2984 km at 135 deg). So this design fixes sigma_1 inside the window and solves for a
constant second-entry bank sigma_2 in ``PROFILE_BOUNDS_RAD``:

* sigma_1 is chosen on a ``FIRST_ENTRY_SCAN_STEP_RAD`` grid among the banks whose nominal
  skips and lands with every scanned second-entry bank and brackets the target between the
  profile bounds: the one deepest inside the window (the first-entry corrector's margin
  against a skip-out and a direct entry), then the one whose estimated sigma_2 (linear
  interpolation of the scanned chute ranges) is nearest 90 deg, the largest control margin
  (the seed's design criterion);
* sigma_2 is the root of "chute on the target", a bounded regula-falsi solve.

Where no first-entry bank brackets the target, :func:`solve_profile_design` returns the chute
ranges its scan brackets (:func:`reachable_intervals`, what the refusal states): one interval
per usable first-entry bank, and their union need not be one interval (near the overshoot
boundary a 0.25 deg step of sigma_1 moves the chute range by more than the second-entry bank
does). Its bank bounds are arguments: the design at the footprint's edge
(:func:`~gnc_jax.guidance.entry.design.design_at_the_edge`) scans wider ones.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from ...root_finding import bounded_regula_falsi
from .base import flight_variables
from .nominal import (
    PROFILE_BOUNDS_RAD,
    RANGE_TOLERANCE_M,
    SIGMA_1_BOUNDS_RAD,
    SKIP_LANDS,
    V_SWITCH_INIT_MPS,
    NominalProblem,
    fly_nominal,
    range_error_m,
)
from .reach import candidate_flights

FIRST_ENTRY_SCAN_STEP_RAD = math.radians(0.25)
PROFILE_SCAN_RAD = np.linspace(*PROFILE_BOUNDS_RAD, 7)  # 45..135 deg every 15 deg
PROFILE_STEP_RAD = math.radians(5.0)  # bracketing step of the sigma_2 solve


@jax.jit
def _solve_profile_bank(problem: NominalProblem, sigma_1, guess, lo, hi):
    """The constant second-entry bank (rad, within ``lo`` .. ``hi``) putting the chute on the
    target with first-entry bank ``sigma_1``, and the nominal's switch speed (m/s)."""

    def residual(s2):
        return range_error_m(problem, fly_nominal(problem, sigma_1, s2, s2, V_SWITCH_INIT_MPS))

    s2 = bounded_regula_falsi(
        residual, guess, PROFILE_STEP_RAD, lo, hi, RANGE_TOLERANCE_M, 20, 30
    ).x
    flight = fly_nominal(problem, sigma_1, s2, s2, V_SWITCH_INIT_MPS)
    return s2, flight_variables(flight.switch, problem.model.earth).speed_mps


def choose_first_entry_bank(err_m: np.ndarray, fate: np.ndarray) -> int | None:
    """Row of the scan (first-entry banks x ``PROFILE_SCAN_RAD``; chute range errors
    ``err_m`` and fates ``fate``) to fix sigma_1 at, or None: of the rows that skip and land
    at every scanned second-entry bank and whose errors change sign across the row (falling
    with the bank), the one farthest (in rows) from a row that does not skip and land at
    every scanned bank, the margin the first-entry corrector has against a skip-out or a
    direct entry; ties to the one whose interpolated root is nearest 90 deg."""
    lands = (fate == SKIP_LANDS).all(axis=1)
    brackets = lands & (err_m[:, 0] >= 0.0) & (err_m[:, -1] <= 0.0)
    if not brackets.any():
        return None
    rows = np.flatnonzero(brackets)
    edges = np.flatnonzero(~lands)
    edges = np.concatenate([[-1], edges, [lands.size]])
    depth = np.min(np.abs(rows[:, None] - edges[None, :]), axis=1)
    # the errors fall with the bank: interpolate the root on the reversed (rising) sequence
    roots = np.array([np.interp(0.0, -err_m[i], PROFILE_SCAN_RAD) for i in rows])
    return int(rows[np.lexsort((np.abs(roots - math.pi / 2), -depth))[0]])


def reachable_intervals(err_m: np.ndarray, fate: np.ndarray) -> list[tuple[float, float]]:
    """The chute range errors (m) for which :func:`choose_first_entry_bank` finds a row, as
    disjoint intervals in increasing order: the union of ``[err_m[i, -1], err_m[i, 0]]`` over
    the rows ``i`` that skip and land at every scanned second-entry bank. The scan's flights
    do not depend on the target's range (it lies on the entry's track), so a target ``d`` m
    farther shifts every error by ``-d`` and is bracketed exactly when ``d`` lies in one of
    these intervals."""
    lands = (fate == SKIP_LANDS).all(axis=1)
    return merged_intervals(
        (float(err_m[i, -1]), float(err_m[i, 0]))
        for i in np.flatnonzero(lands)
        if err_m[i, 0] >= err_m[i, -1]
    )


def merged_intervals(spans) -> list[tuple[float, float]]:
    """The union of the intervals ``spans`` (``(lo, hi)`` pairs) as disjoint intervals in
    increasing order."""
    merged: list[tuple[float, float]] = []
    for lo, hi in sorted(spans):
        if merged and lo <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], hi))
        else:
            merged.append((lo, hi))
    return merged


def first_entry_banks(first_entry_bounds=SIGMA_1_BOUNDS_RAD) -> np.ndarray:
    """The first-entry banks (rad) of the design's scan: a ``FIRST_ENTRY_SCAN_STEP_RAD`` grid
    over ``first_entry_bounds``, both bounds included."""
    lo, hi = first_entry_bounds
    return np.append(np.arange(lo, hi, FIRST_ENTRY_SCAN_STEP_RAD), hi)


def first_entry_scan(
    problem: NominalProblem,
    first_entry_bounds=SIGMA_1_BOUNDS_RAD,
    profile_bounds=PROFILE_BOUNDS_RAD,
):
    """The design's scan: ``(banks, scan, err_m, fate)``, the first-entry banks (rad, a
    ``FIRST_ENTRY_SCAN_STEP_RAD`` grid over ``first_entry_bounds``), the constant
    second-entry banks (rad, ``PROFILE_SCAN_RAD`` or as many over ``profile_bounds``) and the
    chute range errors (m) and fates of the nominal flown with each pair (banks x scan)."""
    banks = first_entry_banks(first_entry_bounds)
    scan = (
        PROFILE_SCAN_RAD
        if tuple(profile_bounds) == PROFILE_BOUNDS_RAD
        else np.linspace(*profile_bounds, PROFILE_SCAN_RAD.size)
    )
    flights = candidate_flights(problem, jnp.asarray(banks), jnp.asarray(scan))
    err_m, fate = (np.asarray(x) for x in flights)
    return banks, scan, err_m, fate


def solve_profile_design(
    problem: NominalProblem,
    first_entry_bounds=SIGMA_1_BOUNDS_RAD,
    profile_bounds=PROFILE_BOUNDS_RAD,
):
    """``(sigma_1, sigma_2, v_switch)`` of the design described in the module docstring, or
    ``(None, reach_m, None)``: no first-entry bank brackets the target; ``reach_m`` the
    chute range errors (m, along track, > 0 beyond the target) the scan brackets
    (:func:`reachable_intervals`; empty when no row skips and lands at every scanned
    second-entry bank). ``first_entry_bounds``, ``profile_bounds``: the banks (rad) sigma_1
    and sigma_2 are sought within."""
    banks, scan, err_m, fate = first_entry_scan(problem, first_entry_bounds, profile_bounds)
    row = choose_first_entry_bank(err_m, fate)
    if row is None:
        return None, reachable_intervals(err_m, fate), None
    guess = float(np.interp(0.0, -err_m[row], scan))
    s2, v_switch = _solve_profile_bank(
        problem, jnp.asarray(banks[row]), jnp.asarray(guess), *map(jnp.asarray, profile_bounds)
    )
    return float(banks[row]), float(s2), float(v_switch)
