"""The chute ranges the reference design reaches, found before it runs.

The design (:mod:`gnc_jax.guidance.entry.design`) first solves for the first-entry bank with
the second-entry profile its optimiser moves, then falls back to the profile design of
:mod:`gnc_jax.guidance.entry.profile_solve`, then to the far-bank design
(:func:`far_bank_design`): the first-entry bank solved inside a window of first-entry banks
that skip and land, with the constant second-entry bank ``FAR_REACH_BANK_RAD``. Its ranges
are the union of those the profile design's scan brackets
(:func:`~.profile_solve.reachable_intervals`: the short end of the footprint and its middle,
with gaps where a scan step of the first-entry bank moves the chute more than the
second-entry bank does), those of the far-bank design's windows, bisected to their edges
(:func:`constant_bank_reach`: the gaps and the far end), and the optimiser's, which lie
inside the first two wherever measured (below). So :func:`require_design_reach` refuses, in
seconds, exactly the targets that no stage of the design puts the chute on.

The reach check of :mod:`gnc_jax.guidance.entry.reach` bounds the chute ranges of every pair
of banks, min to max; between that hull and this union (beyond the skip-out of the far bank,
where only lift-down second entries still land) no stage of the design reaches, and its
stages take 2.5 min in a new process to fail there (the packaged capsule at 12 100 km, inside
the hull 1802 .. 12 901 km).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from ...schema import ScenarioError
from .base import flight_variables
from .nominal import (
    PROFILE_BOUNDS_RAD,
    SKIP_LANDS,
    V_SWITCH_INIT_MPS,
    NominalProblem,
    fate_of,
    fly_nominal,
    fly_nominal_jit,
    range_error_m,
)
from .profile_solve import (
    first_entry_banks,
    first_entry_scan,
    merged_intervals,
    reachable_intervals,
)
from .reach import candidate_flights, conditions

# The constant second-entry bank of the far-bank design (far_bank_design), whose windows end
# the design's reach beyond the profile design's. The optimiser puts the chute on a far target
# with a first-entry bank near the edge of the skip window, where the skip goes farther the
# nearer the edge, up to the skip-out, so its reach ends where the nominal with its own
# second-entry profile skips out, about where a constant bank at the profile's mean does; for
# far targets that profile settles at sigma_a 45..60.6 deg and sigma_b 45..56.5 deg, means up
# to 58.1 deg (the packaged capsule at -5.9, -5.3 and -6.5 deg, at 10.5, 11.5 and 13 km/s,
# L/D 0.26 and 0.34). It designed 0.5 km beyond the skip-out of 57.5 deg (L/D 0.34: -5.3 deg
# 12 006.9 against 12 006.4 km; -6.5 deg, 13 km/s, 12 089.6 against 12 089.1 km); at 60 deg
# its last design is 45 km or more short of it at every condition measured (-5.9 deg:
# 11 850 km, refused at 11 868 km, against 12 009 km; 10.5 km/s, L/D 0.26: 11 794 against
# 11 941 km; 13 km/s, L/D 0.34: 12 341 against 12 640 km; L/D 0.26: none beyond the profile
# design's 9554 km against 12 789 km), and 5 km beyond it no stage of the design reaches.
# Flown (8 runs), the far-bank designs 5..10 km short of that skip-out do as the optimiser's
# do at its own far end, the same runs failing: -5.9 deg 12 000 km 8 ok (the optimiser's
# 11 850 km: 8 ok); 10.5 km/s, L/D 0.26, 11 936 km 3 ok and 5 missed (11 790 km: the same);
# -5.3 deg, L/D 0.34, 12 049 km 8 ok; 13 km/s, L/D 0.34, 12 635 km 6 ok (12 341 km: 6 ok);
# L/D 0.26 (at 57.5 deg) 11 000 and 12 700 km 5 and 3 ok (the profile design's 9500 km: none
# ok). The packaged capsule at -5.9 deg reaches 11 781 km at 45 deg and 12 901 km at 135 deg.
FAR_REACH_BANK_RAD = math.radians(60.0)
EDGE_BATCH = 8  # window edges bisected per compiled call (one shape, compiled once)


@jax.jit
def _edges(problem: NominalProblem, inside, outside, sigma_2):
    """The first-entry bank (rad) at the edge of a window of banks that skip and land, between
    each ``inside`` bank (skips and lands) and its ``outside`` neighbour (does not), bisected
    to 2e-9 of their spacing with the constant second-entry bank ``sigma_2``, and its chute
    range error (m)."""

    def lands_with(sigma_1):
        flight = fly_nominal(problem, sigma_1, sigma_2, sigma_2, V_SWITCH_INIT_MPS)
        return fate_of(flight) == SKIP_LANDS

    def edge(a, b):
        def bisect(_, ends):
            inside, outside = ends
            mid = 0.5 * (inside + outside)
            m = lands_with(mid)
            return jnp.where(m, mid, inside), jnp.where(m, outside, mid)

        inside, _ = jax.lax.fori_loop(0, 30, bisect, (a, b))
        flight = fly_nominal(problem, inside, sigma_2, sigma_2, V_SWITCH_INIT_MPS)
        return inside, range_error_m(problem, flight)

    return jax.vmap(edge)(inside, outside)


def constant_bank_windows(problem: NominalProblem, banks, sigma_2):
    """The windows of first-entry banks whose nominal with the constant second-entry bank
    ``sigma_2`` (rad) skips and lands, among ``banks`` (rad, increasing): for each run of
    neighbouring banks that skip and land, ``(banks, errors)`` in increasing bank order, the
    run's banks and their chute range errors (m) with the window's edges beyond the run
    (bisected; the chute range is continuous in the first-entry bank up to an edge, where the
    skip flattens into a direct entry or skips out)."""
    flights = candidate_flights(problem, jnp.asarray(banks), jnp.asarray([sigma_2]))
    err_m, fate = (np.asarray(x)[:, 0] for x in flights)
    rows = np.flatnonzero(fate == SKIP_LANDS)
    if rows.size == 0:
        return []
    cut = np.flatnonzero(np.diff(rows) > 1)
    runs = list(zip(rows[np.r_[0, cut + 1]], rows[np.r_[cut, rows.size - 1]], strict=True))
    pairs = [  # (run, inside, outside)
        (k, i, o)
        for k, (a, b) in enumerate(runs)
        for i, o in ((a, a - 1), (b, b + 1))
        if 0 <= o < len(banks)
    ]
    edge_banks, edge_errors = np.zeros(len(pairs)), np.zeros(len(pairs))
    for n in range(0, len(pairs), EDGE_BATCH):
        chunk = pairs[n : n + EDGE_BATCH]
        chunk_full = chunk + [chunk[-1]] * (EDGE_BATCH - len(chunk))
        inside = jnp.asarray([banks[i] for _, i, _ in chunk_full])
        outside = jnp.asarray([banks[o] for _, _, o in chunk_full])
        found = _edges(problem, inside, outside, jnp.asarray(sigma_2))
        edge_banks[n : n + len(chunk)] = np.asarray(found[0])[: len(chunk)]
        edge_errors[n : n + len(chunk)] = np.asarray(found[1])[: len(chunk)]
    windows = []
    for k, (a, b) in enumerate(runs):
        ends = [n for n, (j, _, _) in enumerate(pairs) if j == k]
        window_banks = np.concatenate([banks[a : b + 1], edge_banks[ends]])
        errors = np.concatenate([err_m[a : b + 1], edge_errors[ends]])
        order = np.argsort(window_banks)
        windows.append((window_banks[order], errors[order]))
    return windows


def constant_bank_reach(problem: NominalProblem, banks, sigma_2) -> list[tuple[float, float]]:
    """The chute range errors (m) of the nominal flown with the first-entry ``banks`` (rad,
    increasing) and the constant second-entry bank ``sigma_2`` (rad), as disjoint intervals in
    increasing order: those of each window of :func:`constant_bank_windows`, min to max."""
    spans = [
        (float(errors.min()), float(errors.max()))
        for _, errors in constant_bank_windows(problem, banks, sigma_2)
    ]
    return merged_intervals(spans)


ROOT_REFINEMENTS = 4  # grids of the far-bank root: each narrows the bracket (banks - 1) fold


def _first_entry_root(problem: NominalProblem, a, b, sigma_2, size: int):
    """The first-entry bank (rad) between ``a`` and ``b`` (chute range errors of opposite
    signs, in one window that skips and lands) that puts the chute on the target with the
    constant second-entry bank ``sigma_2``: ``ROOT_REFINEMENTS`` grids of ``size`` banks
    (:func:`~.reach.candidate_flights`, the program the reach check compiled), each over the
    neighbours of the last where the error changes sign, both skipping and landing (from
    0.25 deg: 4e-14 rad, well under a metre at the skip-out's steepest). None when a grid finds
    no such neighbours (a gap inside the window)."""
    for _ in range(ROOT_REFINEMENTS):
        grid = np.linspace(a, b, size)
        flights = candidate_flights(problem, jnp.asarray(grid), jnp.asarray([sigma_2]))
        err_m, fate = (np.asarray(x)[:, 0] for x in flights)
        lands = fate == SKIP_LANDS
        change = lands[:-1] & lands[1:] & (np.sign(err_m[:-1]) != np.sign(err_m[1:]))
        if not change.any():
            return None
        k = int(np.argmax(change))
        a, b, ends = grid[k], grid[k + 1], err_m[k : k + 2]
    return float(a if abs(ends[0]) <= abs(ends[1]) else b)


def far_bank_design(problem: NominalProblem):
    """``(sigma_1, v_switch)``: the first-entry bank (rad) putting the chute on the target
    with the constant second-entry bank ``FAR_REACH_BANK_RAD``, and the nominal's switch speed
    (m/s); None when no window of :func:`constant_bank_windows` (the first-entry banks of the
    profile design's scan) holds the target. This is the design of the ranges
    :func:`design_reach` adds to the profile design's. Of the neighbouring banks (edges
    included) whose errors bracket the target, the pair deepest inside its window: the
    first-entry corrector's margin against a skip-out or a direct entry."""
    banks = first_entry_banks()
    best = None
    for window_banks, errors in constant_bank_windows(problem, banks, FAR_REACH_BANK_RAD):
        for i in np.flatnonzero(errors[:-1] * errors[1:] <= 0.0):
            depth = min(i, len(errors) - 2 - i)
            if best is None or depth > best[0]:
                best = (depth, window_banks[i], window_banks[i + 1])
    if best is None:
        return None
    _, a, b = best
    sigma_1 = _first_entry_root(problem, a, b, FAR_REACH_BANK_RAD, banks.size)
    if sigma_1 is None:
        return None
    flight = fly_nominal_jit(
        problem, sigma_1, FAR_REACH_BANK_RAD, FAR_REACH_BANK_RAD, V_SWITCH_INIT_MPS
    )
    return sigma_1, float(flight_variables(flight.switch, problem.model.earth).speed_mps)


def design_reach(problem: NominalProblem) -> list[tuple[float, float]]:
    """The chute range errors (m, along track, > 0 beyond the target) the reference design
    reaches (module docstring), as disjoint intervals in increasing order: the profile
    design's (:func:`~.profile_solve.reachable_intervals` of its scan) and the nominal's with
    the constant second-entry bank ``FAR_REACH_BANK_RAD`` (:func:`constant_bank_reach`)."""
    banks, _, err_m, fate = first_entry_scan(problem)
    return merged_intervals(
        reachable_intervals(err_m, fate) + constant_bank_reach(problem, banks, FAR_REACH_BANK_RAD)
    )


def intervals_text(intervals_m, range_km: float) -> str:
    """Chute range errors (m) as ranges (km): "a .. b km", "a .. b or c .. d km",
    "a .. b, c .. d or e .. f km"."""
    parts = [f"{range_km + lo / 1e3:.0f} .. {range_km + hi / 1e3:.0f}" for lo, hi in intervals_m]
    if len(parts) > 1:
        parts = [", ".join(parts[:-1]) + " or " + parts[-1]]
    return f"{parts[0]} km"


def range_refusal(entry: dict, vehicle: dict, reach: str) -> ScenarioError:
    """The refusal of a target the design does not reach, naming ``entry.range_km`` with
    ``reach``, what it reaches."""
    return ScenarioError(
        f"entry.range_km: {entry['range_km']:g} km; allowed: a range the reference design "
        f"reaches with a skip ({reach}; {conditions(entry, vehicle)})"
    )


def require_design_reach(problem: NominalProblem, entry: dict, vehicle: dict):
    """Refuse (:func:`range_refusal`), before the design runs, a target outside
    :func:`design_reach` (the first-entry scan of the profile design, a few seconds)."""
    reach_m = design_reach(problem)
    if not any(lo <= 0.0 <= hi for lo, hi in reach_m):
        raise range_refusal(
            entry,
            vehicle,
            intervals_text(reach_m, entry["range_km"])
            if reach_m
            else "none: no first-entry bank skips and lands with the second-entry bank at "
            f"{math.degrees(FAR_REACH_BANK_RAD):g} deg or with every one from "
            f"{math.degrees(PROFILE_BOUNDS_RAD[0]):.0f} to "
            f"{math.degrees(PROFILE_BOUNDS_RAD[1]):.0f} deg",
        )
