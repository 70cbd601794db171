"""The chute ranges the reference design reaches, found before it runs.

The design (:mod:`gnc_jax.guidance.entry.design`) first solves for the first-entry bank with
the second-entry profile its optimiser moves, then falls back to the profile design of
:mod:`gnc_jax.guidance.entry.profile_solve`. Its ranges are the union of those the profile
design's scan brackets (:func:`~.profile_solve.reachable_intervals`: the short end of the
footprint and its middle, with gaps where a scan step of the first-entry bank moves the chute
more than the second-entry bank does) and those the nominal reaches with a constant
second-entry bank near the profile the optimiser settles at, over each window of first-entry
banks that skip and land, bisected to the window's edges (:func:`constant_bank_reach` at
``FAR_REACH_BANK_RAD``: the gaps and the far end).

The reach check of :mod:`gnc_jax.guidance.entry.reach` bounds the chute ranges of every pair
of banks, min to max; between that hull and this union (beyond the skip-out of the design's
profile, where only lift-down second entries still land) no stage of the design puts the
chute on the target, and its optimiser, fine retry and profile design take 2.5 min in a new
process to fail there (the packaged capsule at 12 000 km, inside the hull 1802 .. 12 901 km).
Against the design itself (the packaged capsule at -5.9, -5.3 and -6.5 deg, at 10.5 and 11.5
km/s, L/D 0.26 and 0.34; targets 2000 .. 12 500 km) every target it designs lies in this
union.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np

from ...schema import ScenarioError
from .nominal import (
    PROFILE_BOUNDS_RAD,
    SKIP_LANDS,
    V_SWITCH_INIT_MPS,
    NominalProblem,
    fate_of,
    fly_nominal,
    range_error_m,
)
from .profile_solve import first_entry_scan, merged_intervals, reachable_intervals
from .reach import candidate_flights, conditions

# The constant second-entry bank whose nominal ends the design's reach beyond the profile
# design's: the design puts the chute on a far target with a first-entry bank near the edge
# of the skip window, where the skip goes farther the nearer the edge, up to the skip-out, so
# its reach ends where the nominal with its own second-entry profile skips out. That profile
# settles at sigma_a 45..57 deg and sigma_b 45..53 deg for far targets (the packaged capsule
# at -5.9, -5.3 and -6.5 deg, at 10.5 and 11.5 km/s, L/D 0.26 and 0.34), and the reach ends
# where a constant bank near their mean skips out (46..55 deg). A constant 57.5 deg reaches
# 34..155 km farther than the design does there (-5.9 deg: 11 969 km against 11 850 km
# designed and 11 868 km refused; L/D 0.34: 11 890 km, 11 838 km designed): the check accepts
# those targets and the design then refuses them. The packaged capsule at -5.9 deg reaches
# 11 781 km at 45 deg, 12 009 km at 60 deg and 12 901 km at 135 deg.
FAR_REACH_BANK_RAD = math.radians(57.5)
EDGE_BATCH = 8  # window edges bisected per compiled call (one shape, compiled once)


@jax.jit
def _edge_errors(problem: NominalProblem, inside, outside, sigma_2):
    """Chute range error (m) at the edge of a window of first-entry banks that skip and land,
    between each ``inside`` bank (skips and lands) and its ``outside`` neighbour (does not),
    bisected to 2e-9 of their spacing, with the constant second-entry bank ``sigma_2``."""

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
        return range_error_m(problem, flight)

    return jax.vmap(edge)(inside, outside)


def constant_bank_reach(problem: NominalProblem, banks, sigma_2) -> list[tuple[float, float]]:
    """The chute range errors (m) of the nominal flown with the first-entry ``banks`` (rad,
    increasing) and the constant second-entry bank ``sigma_2`` (rad), as disjoint intervals in
    increasing order: for each run of neighbouring banks that skip and land, the errors of the
    run and at the window's edges beyond it (bisected; the chute range is continuous in the
    first-entry bank up to an edge, where the skip flattens into a direct entry or skips
    out)."""
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
    edges = np.zeros(len(pairs))
    for n in range(0, len(pairs), EDGE_BATCH):
        chunk = pairs[n : n + EDGE_BATCH]
        chunk_full = chunk + [chunk[-1]] * (EDGE_BATCH - len(chunk))
        inside = jnp.asarray([banks[i] for _, i, _ in chunk_full])
        outside = jnp.asarray([banks[o] for _, _, o in chunk_full])
        errors = _edge_errors(problem, inside, outside, jnp.asarray(sigma_2))
        edges[n : n + len(chunk)] = np.asarray(errors)[: len(chunk)]
    spans = []
    for k, (a, b) in enumerate(runs):
        ends = [e for (j, _, _), e in zip(pairs, edges, strict=True) if j == k]
        values = np.concatenate([err_m[a : b + 1], ends])
        spans.append((float(values.min()), float(values.max())))
    return merged_intervals(spans)


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
