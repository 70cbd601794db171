"""What the reference design can reach, checked before it runs.

:func:`require_reachable` flies the nominal (:mod:`gnc_jax.guidance.entry.nominal`) with every
first-entry bank the design's solve can try and refuses, naming the scenario field, a target
the design cannot reach: an entry flight-path angle at which no bank skips and lands (with the
corridor of angles that work), or a range outside the chute ranges of those that do (with the
reachable interval).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...schema import ScenarioError
from .base import perturb_switch_state
from .nominal import (
    LANDS_WITHOUT_SKIP,
    NEVER_LANDS,
    PROFILE_BOUNDS_RAD,
    PROFILE_INIT_RAD,
    SIGMA_1_BOUNDS_RAD,
    SIGMA_1_GUESS_RAD,
    SIGMA_1_STEP_RAD,
    SKIP_LANDS,
    V_SWITCH_INIT_MPS,
    NominalProblem,
    fate_of,
    fly_nominal,
    range_error_m,
)

# The reach check's second look (require_reachable) when no coarse candidate skips and lands:
# at the overshoot boundary that window can fall between two coarse candidates (L/D 0.40,
# beta 250 kg/m^2, -5.2 deg, 0.25 deg inside the corridor: refused at the coarse step).
SIGMA_1_REACH_FINE_STEP_RAD = math.radians(0.25)


def candidate_banks(guess=SIGMA_1_GUESS_RAD) -> np.ndarray:
    """The first-entry banks the design's solve can try: steps of ``SIGMA_1_STEP_RAD`` from
    ``guess`` (eq. 15) over the whole of ``SIGMA_1_BOUNDS_RAD``, since the warm start of each
    design step is the previous solution and may drift to either bound."""
    lo, hi = SIGMA_1_BOUNDS_RAD
    k = np.arange(
        np.floor((lo - guess) / SIGMA_1_STEP_RAD), np.ceil((hi - guess) / SIGMA_1_STEP_RAD) + 1
    )
    return np.unique(np.clip(guess + SIGMA_1_STEP_RAD * k, lo, hi))


@jax.jit
def candidate_flights(problem: NominalProblem, banks, profile_banks):
    """Along-track chute error (m) and fate of the nominal flown with each first-entry bank of
    ``banks`` and each constant second-entry bank of ``profile_banks`` (shape: banks x
    profile banks)."""

    def one(sigma_1, sigma_2):
        flight = fly_nominal(problem, sigma_1, sigma_2, sigma_2, V_SWITCH_INIT_MPS)
        return range_error_m(problem, flight), fate_of(flight)

    return jax.vmap(lambda s1: jax.vmap(lambda s2: one(s1, s2))(profile_banks))(banks)


@jax.jit
def _edge_errors(problem: NominalProblem, a, b, a_lands, sigma_2):
    """Along-track chute error (m) where the nominal stops skipping and landing between the
    first-entry banks ``a`` and ``b`` (``a_lands``: whether ``a`` skips and lands) with the
    constant second-entry bank ``sigma_2``, for each such pair (bisection to 2e-9 of the
    interval)."""

    def lands_with(sigma_1, sigma_2):
        flight = fly_nominal(problem, sigma_1, sigma_2, sigma_2, V_SWITCH_INIT_MPS)
        return fate_of(flight) == SKIP_LANDS

    def edge(a, b, a_lands, sigma_2):
        def bisect(_, ends):
            inside, outside = ends
            mid = 0.5 * (inside + outside)
            m = lands_with(mid, sigma_2)
            return jnp.where(m, mid, inside), jnp.where(m, outside, mid)

        ends = (jnp.where(a_lands, a, b), jnp.where(a_lands, b, a))
        inside, _ = jax.lax.fori_loop(0, 30, bisect, ends)
        flight = fly_nominal(problem, inside, sigma_2, sigma_2, V_SWITCH_INIT_MPS)
        return range_error_m(problem, flight)

    return jax.vmap(edge)(a, b, a_lands, sigma_2)


def _boundary_errors(problem: NominalProblem, banks, profile_banks, fate):
    """Along-track chute error (m) where the nominal stops skipping and landing, between
    neighbouring ``banks`` whose ``fate`` (from :func:`candidate_flights`) differs in
    whether they skip and land (0 elsewhere), and where they differ: ``(errors, edge)``,
    both of shape (banks - 1) x profile banks.

    The chute range is continuous in the first-entry bank up to such a boundary (the skip
    flattens into a direct entry, or the Kepler arc lengthens beyond the design horizon), so
    the ranges at the boundaries are the ends of what the design's solve can bracket. Only
    the pairs at a boundary are bisected (a few of the hundreds of neighbours), in a batch
    padded to a power of two so that few batch sizes are compiled."""
    banks, profile_banks = np.asarray(banks), np.asarray(profile_banks)
    lands = np.asarray(fate) == SKIP_LANDS
    edge = lands[:-1] != lands[1:]
    errors = np.zeros(edge.shape)
    i, j = np.nonzero(edge)
    if i.size:
        pad = max(8, 1 << (i.size - 1).bit_length()) - i.size
        i, j = np.pad(i, (0, pad), mode="edge"), np.pad(j, (0, pad), mode="edge")
        pairs = (banks[i], banks[i + 1], lands[i, j], profile_banks[j])
        found = np.asarray(_edge_errors(problem, *(jnp.asarray(x) for x in pairs)))
        errors[i, j] = found
    return errors, edge


def profile_bank_span() -> np.ndarray:
    """Constant second-entry banks spanning what the design may fly: its bounds and start."""
    return np.array([PROFILE_BOUNDS_RAD[0], PROFILE_INIT_RAD[0], PROFILE_BOUNDS_RAD[1]])


@jax.jit
def _skips_and_lands(problem: NominalProblem, d_fpa, banks, profile_banks):
    """Whether some pair of ``banks`` x ``profile_banks`` skips and lands when the entry
    flight-path angle is shifted by each of ``d_fpa`` (rad)."""
    earth = problem.model.earth

    def shifted(d):
        entry = perturb_switch_state(problem.entry, earth, 0.0, d, 0.0)
        return candidate_flights(
            eqx.tree_at(lambda p: p.entry, problem, entry), banks, profile_banks
        )

    return jax.vmap(lambda d: jnp.any(shifted(d)[1] == SKIP_LANDS))(d_fpa)


FPA_RANGE_DEG = (-12.0, -2.0)
"""Entry flight-path angles (deg) the design accepts, the range of ``entry.fpa_deg``: steeper,
the load pulse lasts under three design steps; shallower, nothing is captured."""


def _corridor(problem: NominalProblem, entry: dict, banks) -> str:
    """The entry flight-path angles (deg, 0.1 deg grid over the declared range) for which some
    candidate skips and lands, at this entry speed and vehicle."""
    lo, hi = FPA_RANGE_DEG
    grid = np.round(np.arange(lo, hi + 1e-9, 0.1), 1)
    d_fpa = np.radians(grid - entry["fpa_deg"])
    ok = np.asarray(
        _skips_and_lands(problem, jnp.asarray(d_fpa), jnp.asarray(banks), profile_bank_span())
    )
    if not ok.any():
        return "none at this speed and vehicle (change entry.speed_kmps or vehicle.cl/cd)"
    return f"{grid[ok].max():.1f} .. {grid[ok].min():.1f} deg at this speed and vehicle"


def conditions(entry: dict, vehicle: dict) -> str:
    return (
        f"entry.speed_kmps = {entry['speed_kmps']:g}, entry.fpa_deg = {entry['fpa_deg']:g}, "
        f"L/D = vehicle.cl/vehicle.cd = {vehicle['cl'] / vehicle['cd']:.3g}"
    )


def require_reachable(problem: NominalProblem, entry: dict, vehicle: dict, guess=None):
    """Refuse, before the design runs, a scenario whose target the design cannot reach.

    The design puts the chute on the target by solving for the first-entry bank, starting
    from ``guess`` and bracketing in steps of ``SIGMA_1_STEP_RAD`` (eq. 15). This flies the
    nominal with each of those candidate banks and the design's initial second-entry profile
    (one vmapped, jitted flight, a few seconds) and raises :class:`ScenarioError`:

    * naming ``entry.fpa_deg`` (with the corridor of angles that work at this speed and L/D)
      when no candidate skips and lands: the law needs a skip (seed 003 Fig. 1);
    * naming ``entry.range_km`` (with the reachable interval) when the target lies outside
      the chute ranges of the candidates that skip and land: no bank brackets the target.

    ``entry`` and ``vehicle`` are the scenario sections (file units) the messages quote.
    Returns the reachable interval (km) and the candidate first-entry bank (rad) whose
    nominal, with the design's initial second-entry profile, lands nearest the target: the
    design's first guess.
    """
    banks = candidate_banks(SIGMA_1_GUESS_RAD if guess is None else guess)
    flights = candidate_flights(problem, jnp.asarray(banks), jnp.asarray(profile_bank_span()))
    err_m, fate = (np.asarray(x) for x in flights)
    span = (
        f"first-entry banks {np.degrees(banks.min()):.0f}..{np.degrees(banks.max()):.0f} deg "
        f"and second-entry banks {np.degrees(PROFILE_BOUNDS_RAD[0]):.0f}.."
        f"{np.degrees(PROFILE_BOUNDS_RAD[1]):.0f} deg"
    )
    lands = fate == SKIP_LANDS
    if not lands.any():  # a second look on a fine grid (SIGMA_1_REACH_FINE_STEP_RAD)
        lo, hi = SIGMA_1_BOUNDS_RAD
        fine = np.append(np.arange(lo, hi, SIGMA_1_REACH_FINE_STEP_RAD), hi)
        fine_flights = candidate_flights(
            problem, jnp.asarray(fine), jnp.asarray(profile_bank_span())
        )
        fine_err, fine_fate = (np.asarray(x) for x in fine_flights)
        if (fine_fate == SKIP_LANDS).any():
            banks, err_m, fate = fine, fine_err, fine_fate
            lands = fate == SKIP_LANDS
    if not lands.any():
        if (fate == NEVER_LANDS).all():
            what = "skips out (never reaches the chute altitude)"
        elif (fate == LANDS_WITHOUT_SKIP).all():
            what = "lands without a skip"
        else:
            what = "never both skips and lands"
        raise ScenarioError(
            f"entry.fpa_deg: {entry['fpa_deg']:g} deg; the nominal flight {what} with all "
            f"{span} ({conditions(entry, vehicle)}); allowed: "
            f"{_corridor(problem, entry, banks)}"
        )
    edge_m, edge = _boundary_errors(problem, banks, profile_bank_span(), fate)
    reach_km = entry["range_km"] + np.concatenate([err_m[lands], edge_m[edge]]) / 1e3
    lo, hi = float(reach_km.min()), float(reach_km.max())
    if not lo <= entry["range_km"] <= hi:
        raise ScenarioError(
            f"entry.range_km: {entry['range_km']:g} km; allowed: {lo:.0f} .. {hi:.0f} km, the "
            f"chute ranges of the reference design's nominal skip with {span} "
            f"({conditions(entry, vehicle)})"
        )
    # the design's first solve brackets only SIGMA_1_BRACKET_STEPS steps around its guess,
    # and a guess whose nominal never lands (a flat range error) gives it nothing to follow:
    # near the overshoot boundary the fixed 74 deg guess skipped out and the design failed
    column = int(np.argmin(np.abs(profile_bank_span() - PROFILE_INIT_RAD[0])))
    usable = lands[:, column] if lands[:, column].any() else lands.any(axis=1)
    miss = np.where(usable, np.abs(err_m[:, column]), np.inf)
    return lo, hi, float(banks[int(np.argmin(miss))])
