"""Design of the capsule's second-entry reference profile (seed 003 §2.2).

The seed designs its reference "for maximum control margin and minimum second load peak" but
gives neither the profile nor the weights. gnc_jax designs it itself, reproducibly: on the
nominal flight of :mod:`gnc_jax.guidance.entry.nominal` (sigma_1 solved so that the chute
deploys on the target), (sigma_a, sigma_b) minimise  J = N_g2 + w_margin * max(|cos sigma_1|,
|cos sigma_a|, |cos sigma_b|)  with optax Adam: N_g2 is the second-entry load peak (a smooth
maximum, g) and the cosines measure how close each bank is to full lift up or down (no control
margin). A design that does not converge is retried once with a fine bracketing step, then
replaced by a design with a constant second-entry bank (the profile design, then the far-bank
design), then refused.
"""

import math
import sys
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ...schema import ScenarioError
from .base import flight_variables
from .design_reach import (
    FAR_REACH_BANK_RAD,
    far_bank_design,
    intervals_text,
    range_refusal,
    require_design_reach,
)
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
    fly_nominal_jit,
    range_error_m,
    solve_first_entry_bank,
)
from .profile_solve import solve_profile_design
from .reach import candidate_banks, candidate_flights, conditions

# The fallback of a design whose solve did not converge (see design_with_fallback): at the
# overshoot boundary the first-entry banks that skip and land span about 2.5 deg (v1, -5.3
# deg: 118.1..120.6 deg, a skip-out below, a direct entry or a second-entry skip-out above),
# narrower than SIGMA_1_STEP_RAD, and the chute range is not monotone in them; the coarse
# bracketing then straddles the jump to the direct entry and the solve stalls at its guess.
SIGMA_1_FINE_STEP_RAD = math.radians(0.05)
DESIGN_MISS_LIMIT_M = 1.0e3  # a designed nominal farther from the target did not converge
# The design at the footprint's edge (design_at_the_edge), for a target beyond the reach of
# the banks above but inside the vehicle's constant-bank footprint (a steep entry's lofted
# skip near full lift up): first-entry banks from full lift up, second-entry banks down to
# the tracking law's smallest bank (track_bank_min_deg). Such a design leaves the law little
# bank for the dispersions; the study says how many runs it then brings to the target.
EDGE_FIRST_ENTRY_BOUNDS_RAD = (0.0, math.radians(165.0))
EDGE_PROFILE_BOUNDS_RAD = (math.radians(15.0), math.radians(165.0))


class DesignResult(NamedTuple):
    sigma_1: float
    sigma_a: float
    sigma_b: float
    v_switch: float
    objective_history: list


def _design_objective(
    problem: NominalProblem, theta, v_switch, guess, w_margin, step=SIGMA_1_STEP_RAD
):
    """J = N_g2 + w_margin * smooth max of the bank cosines, with (sigma_1, switch speed)."""
    s1 = solve_first_entry_bank(problem, theta[0], theta[1], v_switch, guess, step)
    fl = fly_nominal(problem, s1, theta[0], theta[1], v_switch)
    cosines = jnp.abs(jnp.cos(jnp.stack([s1, theta[0], theta[1]])))
    margin = jnp.log(jnp.sum(jnp.exp(20.0 * cosines))) / 20.0
    return fl.peak2 + w_margin * margin, (
        s1,
        flight_variables(fl.switch, problem.model.earth).speed_mps,
    )


# The design's compiled steps take the problem as an argument (not a closure), so that every
# design after the first of a process reuses them: compilation was about 45 s of each design.
_design_value_and_grad = jax.jit(jax.value_and_grad(_design_objective, argnums=1, has_aux=True))
_solve_first_entry_bank = jax.jit(solve_first_entry_bank)


def design(
    problem: NominalProblem,
    w_margin=2.0,
    steps=20,
    learning_rate=0.05,
    init=PROFILE_INIT_RAD,
    sigma_1_guess=SIGMA_1_GUESS_RAD,
    callback=None,
    sigma_1_step=SIGMA_1_STEP_RAD,
):
    """Optimise (sigma_a, sigma_b); returns the design (radians) and the objective history.

    ``callback(step, objective)``, if given, is called after each optimiser step (progress);
    ``sigma_1_step`` is the bracketing step of the first-entry bank solve."""
    v_switch = jnp.asarray(V_SWITCH_INIT_MPS)
    w = jnp.asarray(w_margin, dtype=jnp.float64)
    theta = jnp.asarray(init)
    opt = optax.adam(learning_rate)
    state = opt.init(theta)
    history = []
    guess = jnp.asarray(sigma_1_guess)
    for _ in range(steps):
        (value, (s1, vs)), g = _design_value_and_grad(
            problem, theta, v_switch, guess, w, jnp.asarray(sigma_1_step)
        )
        history.append(float(value))
        if callback is not None:
            callback(len(history), history[-1])
        updates, state = opt.update(g, state)
        theta = jnp.clip(optax.apply_updates(theta, updates), *PROFILE_BOUNDS_RAD)
        # anchor the profile at the switch speed the design actually produces
        v_switch, guess = vs, s1
    s1 = _solve_first_entry_bank(
        problem, theta[0], theta[1], v_switch, guess, jnp.asarray(sigma_1_step)
    )
    return DesignResult(float(s1), float(theta[0]), float(theta[1]), float(v_switch), history)


def fine_first_entry_guess(problem: NominalProblem, guess=SIGMA_1_GUESS_RAD):
    """A first guess for a design whose solve at ``SIGMA_1_STEP_RAD`` failed: the first-entry
    bank, on a ``SIGMA_1_FINE_STEP_RAD`` grid within one coarse step of the coarse candidates
    (:func:`~gnc_jax.guidance.entry.reach.candidate_banks` from ``guess``) that skip and land
    with the initial profile, at the end nearest the target of a fine interval over which both
    ends skip and land and the chute range error falls through zero (the solve's
    ``decreasing`` assumption holds there). None when there is no such interval."""
    coarse = candidate_banks(guess)
    profile = jnp.asarray([PROFILE_INIT_RAD[0]])
    _, fate = (np.asarray(x)[:, 0] for x in candidate_flights(problem, coarse, profile))
    lands = coarse[fate == SKIP_LANDS]
    if lands.size == 0:
        return None
    lo, hi = SIGMA_1_BOUNDS_RAD
    n = int(round(SIGMA_1_STEP_RAD / SIGMA_1_FINE_STEP_RAD))
    fine = np.unique(
        np.clip(lands[:, None] + SIGMA_1_FINE_STEP_RAD * np.arange(-n, n + 1), lo, hi).ravel()
    )
    err, fate = (np.asarray(x)[:, 0] for x in candidate_flights(problem, fine, profile))
    ok = (fate[:-1] == SKIP_LANDS) & (fate[1:] == SKIP_LANDS)
    falls = ok & (err[:-1] > 0.0) & (err[1:] <= 0.0) & (np.diff(fine) < 1.5 * SIGMA_1_FINE_STEP_RAD)
    if not falls.any():
        return None
    i = np.flatnonzero(falls)
    nearer = np.where(np.abs(err[i]) <= np.abs(err[i + 1]), i, i + 1)
    return float(fine[nearer[np.argmin(np.abs(err[nearer]))]])


def design_with_fallback(problem: NominalProblem, entry: dict, vehicle: dict, **kwargs):
    """:func:`design`; if it did not converge (:func:`require_design`), once more with the
    fine bracketing step ``SIGMA_1_FINE_STEP_RAD`` from :func:`fine_first_entry_guess` (the
    overshoot boundary, where the banks that skip and land are a window narrower than the
    coarse step); if that fails too, the design that fixes the first-entry bank and meets the
    range with a constant second-entry bank (:func:`design_by_profile`); then the design that
    meets it with the first-entry bank and the constant second-entry bank
    ``FAR_REACH_BANK_RAD`` (:func:`~.design_reach.far_bank_design`: the ranges beyond the
    optimiser's far end and in the profile design's gaps). A target none of them brackets is
    refused with the ranges they reach (:func:`~.design_reach.require_design_reach`, the check
    that runs before the design). A design that converges at the coarse step is returned as
    it is."""
    d = design(problem, **kwargs)
    try:
        require_design(problem, d, entry, vehicle)
        return d
    except ScenarioError:
        guess = fine_first_entry_guess(problem, kwargs.get("sigma_1_guess", SIGMA_1_GUESS_RAD))
    if guess is not None:
        fine = dict(kwargs, sigma_1_guess=guess, sigma_1_step=SIGMA_1_FINE_STEP_RAD)
        d = design(problem, **fine)
        try:
            require_design(problem, d, entry, vehicle)
            return d
        except ScenarioError:
            pass
    try:
        d = design_by_profile(problem, entry, vehicle)
        require_design(problem, d, entry, vehicle)
        return d
    except ScenarioError as refusal:
        far = far_bank_design(problem)
        if far is None:  # beyond every stage: refused with what they reach
            require_design_reach(problem, entry, vehicle)
            raise refusal from None
    sigma_1, v_switch = far
    d = DesignResult(sigma_1, FAR_REACH_BANK_RAD, FAR_REACH_BANK_RAD, v_switch, [])
    require_design(problem, d, entry, vehicle)
    return d


def design_by_profile(
    problem: NominalProblem, entry: dict, vehicle: dict, bounds=None
) -> DesignResult:
    """The design of :mod:`gnc_jax.guidance.entry.profile_solve`: sigma_1 fixed inside the
    window of banks that skip and land, the range met by a constant second-entry bank
    (``sigma_a = sigma_b``). Refuses (:class:`ScenarioError`, naming ``entry.range_km``) a
    target no first-entry bank brackets, with the chute ranges the design reaches (one or
    more intervals). ``bounds``: (first-entry, second-entry) bank bounds (rad); default the
    design's own."""
    sigma_1, a, b = solve_profile_design(problem, *(bounds or ()))
    if sigma_1 is None:  # a: the chute range errors the scan brackets (m, intervals)
        lo2, hi2 = (math.degrees(x) for x in (PROFILE_BOUNDS_RAD if bounds is None else bounds[1]))
        raise range_refusal(
            entry,
            vehicle,
            intervals_text(a, entry["range_km"])
            if a
            else "none: no first-entry bank skips and lands with every second-entry bank "
            f"from {lo2:.0f} to {hi2:.0f} deg",
        )
    return DesignResult(sigma_1, a, a, b, [])


def design_at_the_edge(
    problem: NominalProblem, entry: dict, vehicle: dict, refusal: ScenarioError
) -> DesignResult:
    """:func:`design_by_profile` within ``EDGE_FIRST_ENTRY_BOUNDS_RAD`` and
    ``EDGE_PROFILE_BOUNDS_RAD``, for a target the design's own banks do not reach
    (``refusal``, the reach check's). Says so on stderr, with the banks it chose. If the edge
    design fails too, raises ``refusal`` with what the edge design reaches added."""
    banks = _edge_banks()
    try:
        d = design_by_profile(
            problem, entry, vehicle, (EDGE_FIRST_ENTRY_BOUNDS_RAD, EDGE_PROFILE_BOUNDS_RAD)
        )
        require_design(problem, d, entry, vehicle)
    except ScenarioError as e:
        # what the edge design allows, without a second "allowed:" on the refusal's line
        head, allowed, rest = str(e).partition("; allowed: ")
        rest = rest if allowed else head.partition("; ")[2]
        raise ScenarioError(f"{refusal}; with {banks} too: {rest}") from None
    print(edge_notice(entry, d), file=sys.stderr, flush=True)
    return d


def _edge_banks() -> str:
    lo1, hi1 = (f"{math.degrees(x):.0f}" for x in EDGE_FIRST_ENTRY_BOUNDS_RAD)
    lo2, hi2 = (f"{math.degrees(x):.0f}" for x in EDGE_PROFILE_BOUNDS_RAD)
    return f"first-entry banks {lo1}..{hi1} deg and second-entry banks {lo2}..{hi2} deg"


def edge_notice(entry: dict, d: "DesignResult") -> str:
    """What :func:`design_at_the_edge` says of the design ``d`` it made (kept with the cached
    reference, which says it again when it is read back)."""
    banks = _edge_banks()
    return (
        f"gnc_jax: entry.range_km {entry['range_km']:g} km is beyond the design's first-entry "
        f"banks; designed at the edge of the footprint with {banks}: first-entry bank "
        f"{math.degrees(d.sigma_1):.1f} deg, second-entry bank {math.degrees(d.sigma_a):.1f} "
        "deg. Little bank is left there for the dispersions."
    )


def require_design(problem: NominalProblem, d: "DesignResult", entry: dict, vehicle: dict):
    """Refuse (:class:`ScenarioError`, naming ``entry.range_km``) a finished design whose
    nominal does not skip and put the chute on the target: its solve did not converge."""
    flight = fly_nominal_jit(problem, d.sigma_1, d.sigma_a, d.sigma_b, d.v_switch)
    err_m = float(range_error_m(problem, flight))
    fate = int(fate_of(flight))
    if fate != SKIP_LANDS or not abs(err_m) <= DESIGN_MISS_LIMIT_M:
        how = {
            SKIP_LANDS: f"its chute point is {err_m / 1e3:.3g} km from the target",
            LANDS_WITHOUT_SKIP: "its nominal lands without a skip",
            NEVER_LANDS: "its nominal never reaches the chute altitude",
        }[fate]
        raise ScenarioError(
            f"entry.range_km: {entry['range_km']:g} km; the reference design did not converge "
            f"({how}; {conditions(entry, vehicle)}); allowed: a range the design reaches "
            f"(nearer the middle of its reachable interval), or other reference.w_margin / "
            f"reference.design_steps"
        )
