"""Offline design of the capsule's nominal trajectory and second-entry reference (seed 003 §2.2).

The seed designs its reference "for maximum control margin and minimum second load peak" but
gives neither the profile nor the weights. gnc_jax designs it itself, reproducibly:

* first entry: constant bank sigma_1 (the predictor-corrector's nominal solution);
* second entry: bank linear in Earth-relative speed, sigma_ref(v) from sigma_a at the switch
  speed to sigma_b at ``v_end`` (constant below);
* sigma_1 is the root of "chute deploy on the target" (a bounded regula-falsi solve, with
  implicit gradients through ``lax.custom_root``), so every design meets the range exactly;
* (sigma_a, sigma_b) minimise  J = N_g2 + w_margin * max(|cos sigma_1|, |cos sigma_a|,
  |cos sigma_b|)  with optax Adam: N_g2 is the second-entry load peak (a smooth maximum, g)
  and the cosines measure how close each bank is to full lift up or down (no control margin).

From the designed nominal the module tabulates the second-entry reference against speed
(bank, range to go, Ḣ, drag load, range rate) and differentiates the second-entry range with
respect to the switch-point speed, flight-path angle, altitude and a uniform bank offset (the
partials of seed 003 eqs. 10 and 16).
"""

import hashlib
import importlib.resources
import json
import math
import os
import pathlib
import sys
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from tqdm.auto import tqdm

from ..._types import Array, Float, Scalar
from ...dynamics.entry import EntryState
from ...geometry.sphere import along_cross_track, to_earth_fixed, unit
from ...integrate import rk4_step
from ...root_finding import bounded_regula_falsi
from ...schema import ScenarioError
from .base import (
    EntryModel,
    drag_load_g,
    flight_variables,
    ground_range_m,
    hermite_crossing,
    hermite_state,
    perturb_switch_state,
)
from .reference import ReferenceTrajectory

#: bump when the design procedure changes, so that cached references are redesigned
REFERENCE_VERSION = 5

# The first-entry bank search of the design (solve_first_entry_bank): bounds, bracketing step
# and steps (eq. 15), the first guess, and the second-entry profile the design starts from.
# The first-entry bounds leave the corrector 15 deg of bank either side: the skip's range is
# steep in the first-entry bank, so a little authority covers the dispersions, and 40..140 deg
# (before) refused steep entries inside the reachable footprint (-7.1 deg: 1198..3785 km of a
# constant-bank footprint of 824..10 083 km).
SIGMA_1_BOUNDS_RAD = (math.radians(15.0), math.radians(165.0))
SIGMA_1_STEP_RAD = math.radians(2.0)
# The fallback of a design whose solve did not converge (see design_with_fallback): at the
# overshoot boundary the first-entry banks that skip and land span about 2.5 deg (v1, -5.3
# deg: 118.1..120.6 deg, a skip-out below, a direct entry or a second-entry skip-out above),
# narrower than SIGMA_1_STEP_RAD, and the chute range is not monotone in them; the coarse
# bracketing then straddles the jump to the direct entry and the solve stalls at its guess.
SIGMA_1_FINE_STEP_RAD = math.radians(0.05)
SIGMA_1_BRACKET_STEPS = 12
# The reach check's second look (require_reachable) when no coarse candidate skips and lands:
# at the overshoot boundary that window can fall between two coarse candidates (L/D 0.40,
# beta 250 kg/m^2, -5.2 deg, 0.25 deg inside the corridor: refused at the coarse step).
SIGMA_1_REACH_FINE_STEP_RAD = math.radians(0.25)
SIGMA_1_GUESS_RAD = 1.2915  # 74 deg
PROFILE_INIT_RAD = (1.0472, 1.0472)  # 60 deg
# The second-entry profile keeps cos(sigma) within 0.71 of full lift: the tracking law divides
# the reference's cos(sigma) by the measured L/D ratio, and a 3-sigma low L/D (cl -20 %, cd
# +20 %: x0.67-0.72) must still find lift before track_bank_min_deg (15 deg). With 5..175 deg
# (before) the design settled at 18-20 deg off the nominal point, and the low-L/D runs
# undershot by up to 90 km (-6.8 deg, 4000 km).
PROFILE_BOUNDS_RAD = (math.radians(45.0), math.radians(135.0))  # of (sigma_a, sigma_b)
V_SWITCH_INIT_MPS = 7300.0
RANGE_TOLERANCE_M = 1.0  # of the first-entry bank solve
DESIGN_MISS_LIMIT_M = 1.0e3  # a designed nominal farther from the target did not converge


class NominalProblem(eqx.Module):
    """The design problem: nominal model, entry state, target, phase thresholds."""

    model: EntryModel
    entry: EntryState  # nominal entry state (ECI, t = 0)
    target_fixed: Float[Array, "3"]  # target unit vector, Earth-fixed
    kepler_load_g: Scalar  # seed 003: 0.2 g
    chute_altitude_m: Scalar
    v_end_mps: Scalar  # end of the linear second-entry profile
    dt_s: float = eqx.field(static=True, default=2.0)
    max_steps: int = eqx.field(static=True, default=900)


def reference_bank(sigma_a, sigma_b, v_switch, v_end, speed):
    """sigma_ref(v): linear in speed from sigma_a at v_switch to sigma_b at v_end."""
    s = jnp.clip((v_switch - speed) / (v_switch - v_end), 0.0, 1.0)
    return sigma_a + (sigma_b - sigma_a) * s


class _Flight(NamedTuple):
    y: EntryState
    t: Scalar
    phase: Array  # 0 first entry, 1 after pull-up, 2 second entry
    done: Array
    chute: EntryState
    t_chute: Scalar
    switch: EntryState
    t_switch: Scalar
    peak2: Scalar  # log-sum-exp accumulator of the second-entry load
    apogee: Scalar


def fly_nominal(problem: NominalProblem, sigma_1, sigma_a, sigma_b, v_switch, beta=8.0):
    """Open-loop nominal flight; returns the final _Flight record.

    The second-entry profile is anchored at ``v_switch`` (its nominal switch speed)."""
    m, earth = problem.model, problem.model.earth

    def bank(phase, speed):
        return jnp.where(
            phase < 2, sigma_1, reference_bank(sigma_a, sigma_b, v_switch, problem.v_end_mps, speed)
        )

    def body(c: _Flight, _):
        fv = flight_variables(c.y, earth)
        ng = m.load_g(c.y)
        phase = jnp.where((c.phase == 0) & (fv.hdot_mps > 0), 1, c.phase)
        enter2 = (phase == 1) & (fv.hdot_mps < 0) & (ng >= problem.kepler_load_g)
        switch = jax.tree_util.tree_map(lambda a, b: jnp.where(enter2, a, b), c.y, c.switch)
        t_switch = jnp.where(enter2, c.t, c.t_switch)
        phase = jnp.where(enter2, 2, phase)
        cos_b = jnp.cos(bank(phase, fv.speed_mps))
        f = lambda t, y, a: m.vertical_plane_field(t, y, a)  # noqa: E731
        y1 = rk4_step(f, c.t, c.y, problem.dt_s, cos_b)
        alt0, alt1 = fv.altitude_m, flight_variables(y1, earth).altitude_m
        crossing = ~c.done & (alt1 < problem.chute_altitude_m)
        a0 = f(c.t, c.y, cos_b).v
        a1 = f(c.t + problem.dt_s, y1, cos_b).v
        hd1 = jnp.dot(unit(y1.r), y1.v - jnp.cross(earth.angular_velocity(), y1.r))
        s = hermite_crossing(alt0, fv.hdot_mps, alt1, hd1, problem.dt_s, problem.chute_altitude_m)
        chute_now = hermite_state(c.y, a0, y1, a1, problem.dt_s, s)
        chute = jax.tree_util.tree_map(lambda a, b: jnp.where(crossing, a, b), chute_now, c.chute)
        t_chute = jnp.where(crossing, c.t + s * problem.dt_s, c.t_chute)
        peak2 = c.peak2 + jnp.where((phase == 2) & ~c.done, jnp.exp(beta * ng), 0.0)
        done = c.done | crossing
        y = jax.tree_util.tree_map(lambda a, b: jnp.where(c.done, a, b), c.y, y1)
        return _Flight(
            y,
            c.t + problem.dt_s,
            phase,
            done,
            chute,
            t_chute,
            switch,
            t_switch,
            peak2,
            jnp.maximum(c.apogee, jnp.where(phase == 1, alt0, 0.0)),
        ), None

    z = jnp.zeros(())
    init = _Flight(
        problem.entry,
        z,
        jnp.asarray(0),
        jnp.asarray(False),
        problem.entry,
        z,
        problem.entry,
        z,
        z,
        z,
    )
    out, _ = jax.lax.scan(body, init, None, length=problem.max_steps)
    return out._replace(peak2=jnp.log(out.peak2 + 1e-300) / beta)


def range_error_m(problem: NominalProblem, flight: _Flight) -> Scalar:
    """Along-track miss of the chute point (m, > 0 overshoot); 8000 km if it never landed."""
    earth = problem.model.earth
    u_entry = unit(to_earth_fixed(problem.entry.r, 0.0, earth.rotation_rate))
    u_chute = unit(to_earth_fixed(flight.chute.r, flight.t_chute, earth.rotation_rate))
    along = along_cross_track(u_chute, u_entry, problem.target_fixed)[0]
    return jnp.where(flight.done, along * earth.equatorial_radius_m, 8.0e6)


def solve_first_entry_bank(
    problem: NominalProblem, sigma_a, sigma_b, v_switch, guess, step=SIGMA_1_STEP_RAD
):
    """sigma_1 putting the nominal chute point on the target, with implicit gradients.

    ``step`` (rad) is the bracketing step of the solve (eq. 15), an argument: the fine-step
    retry of :func:`design_with_fallback` reuses the compiled design."""

    def residual(s1):
        return range_error_m(problem, fly_nominal(problem, s1, sigma_a, sigma_b, v_switch))

    def solve(f, x0):
        res = bounded_regula_falsi(
            f,
            x0,
            step,
            *SIGMA_1_BOUNDS_RAD,
            RANGE_TOLERANCE_M,
            n_bracket=SIGMA_1_BRACKET_STEPS,
            n_iter=16,
        )
        return res.x

    return jax.lax.custom_root(residual, guess, solve, lambda g, y: y / g(1.0))


# ---- what the design can reach, checked before it runs ----
SKIP_LANDS, LANDS_WITHOUT_SKIP, NEVER_LANDS = 0, 1, 2  # fates of a nominal flight


def _fate(flight: _Flight) -> Array:
    """``SKIP_LANDS`` when the nominal skips (a switch point before the chute) and then reaches
    the chute altitude, the only flight the design and the law can use; ``LANDS_WITHOUT_SKIP``
    for a direct entry; ``NEVER_LANDS`` when it skips out or lands beyond the design horizon."""
    skip = (flight.phase == 2) & (flight.t_switch < flight.t_chute)
    return jnp.where(
        flight.done & skip, SKIP_LANDS, jnp.where(flight.done, LANDS_WITHOUT_SKIP, NEVER_LANDS)
    )


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
def _candidate_flights(problem: NominalProblem, banks, profile_banks):
    """Along-track chute error (m) and fate of the nominal flown with each first-entry bank of
    ``banks`` and each constant second-entry bank of ``profile_banks`` (shape: banks x
    profile banks)."""

    def one(sigma_1, sigma_2):
        flight = fly_nominal(problem, sigma_1, sigma_2, sigma_2, V_SWITCH_INIT_MPS)
        return range_error_m(problem, flight), _fate(flight)

    return jax.vmap(lambda s1: jax.vmap(lambda s2: one(s1, s2))(profile_banks))(banks)


@jax.jit
def _boundary_errors(problem: NominalProblem, banks, profile_banks, fate):
    """Along-track chute error (m) where the nominal stops skipping and landing, between
    neighbouring ``banks`` whose ``fate`` (from :func:`_candidate_flights`) differs in
    whether they skip and land (bisection to 2e-9 of the bank step; 0 elsewhere).

    The chute range is continuous in the first-entry bank up to such a boundary (the skip
    flattens into a direct entry, or the Kepler arc lengthens beyond the design horizon), so
    the ranges at the boundaries are the ends of what the design's solve can bracket."""
    lands = fate == SKIP_LANDS

    def lands_with(sigma_1, sigma_2):
        flight = fly_nominal(problem, sigma_1, sigma_2, sigma_2, V_SWITCH_INIT_MPS)
        return _fate(flight) == SKIP_LANDS

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

    def column(j):
        return jax.vmap(lambda a, b, la: edge(a, b, la, profile_banks[j]))(
            banks[:-1], banks[1:], lands[:-1, j]
        )

    errors = jax.vmap(column)(jnp.arange(profile_banks.shape[0])).T
    return jnp.where(lands[:-1] != lands[1:], errors, 0.0), lands[:-1] != lands[1:]


def _profile_banks() -> np.ndarray:
    """Constant second-entry banks spanning what the design may fly: its bounds and start."""
    return np.array([PROFILE_BOUNDS_RAD[0], PROFILE_INIT_RAD[0], PROFILE_BOUNDS_RAD[1]])


@jax.jit
def _skips_and_lands(problem: NominalProblem, d_fpa, banks, profile_banks):
    """Whether some pair of ``banks`` x ``profile_banks`` skips and lands when the entry
    flight-path angle is shifted by each of ``d_fpa`` (rad)."""
    earth = problem.model.earth

    def shifted(d):
        entry = perturb_switch_state(problem.entry, earth, 0.0, d, 0.0)
        return _candidate_flights(
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
        _skips_and_lands(problem, jnp.asarray(d_fpa), jnp.asarray(banks), _profile_banks())
    )
    if not ok.any():
        return "none at this speed and vehicle (change entry.speed_kmps or vehicle.cl/cd)"
    return f"{grid[ok].max():.1f} .. {grid[ok].min():.1f} deg at this speed and vehicle"


def _conditions(entry: dict, vehicle: dict) -> str:
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
    flights = _candidate_flights(problem, jnp.asarray(banks), jnp.asarray(_profile_banks()))
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
        fine_flights = _candidate_flights(problem, jnp.asarray(fine), jnp.asarray(_profile_banks()))
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
            f"{span} ({_conditions(entry, vehicle)}); allowed: "
            f"{_corridor(problem, entry, banks)}"
        )
    edge_m, edge = (
        np.asarray(x)
        for x in _boundary_errors(
            problem, jnp.asarray(banks), jnp.asarray(_profile_banks()), jnp.asarray(fate)
        )
    )
    reach_km = entry["range_km"] + np.concatenate([err_m[lands], edge_m[edge]]) / 1e3
    lo, hi = float(reach_km.min()), float(reach_km.max())
    if not lo <= entry["range_km"] <= hi:
        raise ScenarioError(
            f"entry.range_km: {entry['range_km']:g} km; allowed: {lo:.0f} .. {hi:.0f} km, the "
            f"chute ranges of the reference design's nominal skip with {span} "
            f"({_conditions(entry, vehicle)})"
        )
    # the design's first solve brackets only SIGMA_1_BRACKET_STEPS steps around its guess,
    # and a guess whose nominal never lands (a flat range error) gives it nothing to follow:
    # near the overshoot boundary the fixed 74 deg guess skipped out and the design failed
    column = int(np.argmin(np.abs(_profile_banks() - PROFILE_INIT_RAD[0])))
    usable = lands[:, column] if lands[:, column].any() else lands.any(axis=1)
    miss = np.where(usable, np.abs(err_m[:, column]), np.inf)
    return lo, hi, float(banks[int(np.argmin(miss))])


def fine_first_entry_guess(problem: NominalProblem, guess=SIGMA_1_GUESS_RAD):
    """A first guess for a design whose solve at ``SIGMA_1_STEP_RAD`` failed: the first-entry
    bank, on a ``SIGMA_1_FINE_STEP_RAD`` grid within one coarse step of the coarse candidates
    (:func:`candidate_banks` from ``guess``) that skip and land with the initial profile, at
    the end nearest the target of a fine interval over which both ends skip and land and the
    chute range error falls through zero (the solve's ``decreasing`` assumption holds there).
    None when there is no such interval."""
    coarse = candidate_banks(guess)
    profile = jnp.asarray([PROFILE_INIT_RAD[0]])
    _, fate = (np.asarray(x)[:, 0] for x in _candidate_flights(problem, coarse, profile))
    lands = coarse[fate == SKIP_LANDS]
    if lands.size == 0:
        return None
    lo, hi = SIGMA_1_BOUNDS_RAD
    n = int(round(SIGMA_1_STEP_RAD / SIGMA_1_FINE_STEP_RAD))
    fine = np.unique(
        np.clip(lands[:, None] + SIGMA_1_FINE_STEP_RAD * np.arange(-n, n + 1), lo, hi).ravel()
    )
    err, fate = (np.asarray(x)[:, 0] for x in _candidate_flights(problem, fine, profile))
    ok = (fate[:-1] == SKIP_LANDS) & (fate[1:] == SKIP_LANDS)
    falls = ok & (err[:-1] > 0.0) & (err[1:] <= 0.0) & (np.diff(fine) < 1.5 * SIGMA_1_FINE_STEP_RAD)
    if not falls.any():
        return None
    i = np.flatnonzero(falls)
    nearer = np.where(np.abs(err[i]) <= np.abs(err[i + 1]), i, i + 1)
    return float(fine[nearer[np.argmin(np.abs(err[nearer]))]])


def design_with_fallback(problem: NominalProblem, entry: dict, vehicle: dict, **kwargs):
    """:func:`design`, refused by :func:`require_design` if it did not converge; then, once,
    the design again with the fine bracketing step ``SIGMA_1_FINE_STEP_RAD`` from
    :func:`fine_first_entry_guess` (the overshoot boundary, where the banks that skip and land
    are a window narrower than the coarse step), refused in turn if that fails too. A design
    that converges at the coarse step is returned as it is."""
    d = design(problem, **kwargs)
    try:
        require_design(problem, d, entry, vehicle)
        return d
    except ScenarioError:
        guess = fine_first_entry_guess(problem, kwargs.get("sigma_1_guess", SIGMA_1_GUESS_RAD))
        if guess is None:
            raise
    d = design(problem, **dict(kwargs, sigma_1_guess=guess, sigma_1_step=SIGMA_1_FINE_STEP_RAD))
    require_design(problem, d, entry, vehicle)
    return d


def require_design(problem: NominalProblem, d: "DesignResult", entry: dict, vehicle: dict):
    """Refuse (:class:`ScenarioError`, naming ``entry.range_km``) a finished design whose
    nominal does not skip and put the chute on the target: its solve did not converge."""
    flight = _fly_nominal(problem, d.sigma_1, d.sigma_a, d.sigma_b, d.v_switch)
    err_m = float(range_error_m(problem, flight))
    fate = int(_fate(flight))
    if fate != SKIP_LANDS or not abs(err_m) <= DESIGN_MISS_LIMIT_M:
        how = {
            SKIP_LANDS: f"its chute point is {err_m / 1e3:.3g} km from the target",
            LANDS_WITHOUT_SKIP: "its nominal lands without a skip",
            NEVER_LANDS: "its nominal never reaches the chute altitude",
        }[fate]
        raise ScenarioError(
            f"entry.range_km: {entry['range_km']:g} km; the reference design did not converge "
            f"({how}; {_conditions(entry, vehicle)}); allowed: a range the design reaches "
            f"(nearer the middle of its reachable interval), or other reference.w_margin / "
            f"reference.design_steps"
        )


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
_fly_nominal = jax.jit(fly_nominal)


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


def second_entry_range(
    problem: NominalProblem,
    switch: EntryState,
    t_switch,
    sigma_a,
    sigma_b,
    v_switch,
    d_bank=0.0,
    dt_s=1.0,
    max_steps=1200,
    d_cos=0.0,
):
    """Ground range (m) flown from a switch state to the chute with cos(sigma_ref(v) + d_bank)
    + d_cos."""
    m, earth = problem.model, problem.model.earth

    def body(c, _):
        y, t, done, chute, t_chute = c
        fv = flight_variables(y, earth)
        cos_b = (
            jnp.cos(
                reference_bank(sigma_a, sigma_b, v_switch, problem.v_end_mps, fv.speed_mps) + d_bank
            )
            + d_cos
        )
        f = lambda t, y, a: m.vertical_plane_field(t, y, a)  # noqa: E731
        y1 = rk4_step(f, t, y, dt_s, cos_b)
        alt1 = flight_variables(y1, earth)
        crossing = ~done & (alt1.altitude_m < problem.chute_altitude_m)
        s = hermite_crossing(
            fv.altitude_m,
            fv.hdot_mps,
            alt1.altitude_m,
            alt1.hdot_mps,
            dt_s,
            problem.chute_altitude_m,
        )
        now = hermite_state(y, f(t, y, cos_b).v, y1, f(t + dt_s, y1, cos_b).v, dt_s, s)
        chute = jax.tree_util.tree_map(lambda a, b: jnp.where(crossing, a, b), now, chute)
        t_chute = jnp.where(crossing, t + s * dt_s, t_chute)
        y = jax.tree_util.tree_map(lambda a, b: jnp.where(done, a, b), y, y1)
        return (y, t + dt_s, done | crossing, chute, t_chute), None

    init = (
        switch,
        jnp.asarray(t_switch, float),
        jnp.asarray(False),
        switch,
        jnp.asarray(t_switch, float),
    )
    (_, _, _, chute, t_chute), _ = jax.lax.scan(body, init, None, length=max_steps)
    return ground_range_m(switch.r, t_switch, chute.r, t_chute, earth)


class _SecondEntryRecord(NamedTuple):
    """The designed second entry flown at 1 s steps, down to the chute altitude (numpy)."""

    r: np.ndarray
    t: np.ndarray
    speed: np.ndarray
    hdot: np.ndarray
    alt: np.ndarray
    bank: np.ndarray
    ngx: np.ndarray
    v: np.ndarray
    range_to_go: np.ndarray  # ground range to the chute point, m (first n points)
    n: int  # points above the chute altitude


@jax.jit
def _second_entry_steps(problem: NominalProblem, switch, t_sw, sigma_a, sigma_b, v_switch):
    """The designed second entry flown from the switch point at 1 s steps (1200 of them)."""
    m, earth = problem.model, problem.model.earth

    def body(c, _):
        y, t = c
        fv = flight_variables(y, earth)
        bank = reference_bank(sigma_a, sigma_b, v_switch, problem.v_end_mps, fv.speed_mps)
        f = lambda t, y, a: m.vertical_plane_field(t, y, a)  # noqa: E731
        y1 = rk4_step(f, t, y, 1.0, jnp.cos(bank))
        return (y1, t + 1.0), (
            y.r,
            t,
            fv.speed_mps,
            fv.hdot_mps,
            fv.altitude_m,
            bank,
            drag_load_g(y, m),
            y.v,
        )

    return jax.lax.scan(body, (switch, t_sw), None, length=1200)[1]


@jax.jit
def _ranges_to(problem: NominalProblem, r, t, chute_r, chute_t):
    """Ground range (m) from each recorded point ``(r[i], t[i])`` to the chute point."""
    earth = problem.model.earth
    return jax.vmap(lambda ri, ti: ground_range_m(ri, ti, chute_r, chute_t, earth))(r, t)


def _record_second_entry(problem: NominalProblem, d: DesignResult, fl) -> _SecondEntryRecord:
    """Fly the designed second entry from the switch point and record it step by step."""
    r, t, speed, hdot, alt, bank, ngx, v = (
        np.asarray(x)
        for x in _second_entry_steps(
            problem, fl.switch, fl.t_switch, d.sigma_a, d.sigma_b, d.v_switch
        )
    )
    above = alt >= float(problem.chute_altitude_m)
    n = int(np.argmin(above)) if not above.all() else len(alt)
    rng = np.asarray(_ranges_to(problem, r[:n], t[:n], fl.chute.r, fl.t_chute))
    return _SecondEntryRecord(r, t, speed, hdot, alt, bank, ngx, v, rng, n)


@jax.jit
def _node_sensitivities(problem: NominalProblem, r, v, t, sigma_a, sigma_b, v_switch):
    """d(second-entry range)/d(altitude, flight-path angle, uniform cos sigma) from each of the
    states ``(r[i], v[i], t[i])``, by forward-mode autodiff (shape: nodes x 3)."""
    earth = problem.model.earth

    def range_from(ri, vi, ti, x):
        y = perturb_switch_state(EntryState(ri, vi), earth, 0.0, x[1], x[0])
        return second_entry_range(problem, y, ti, sigma_a, sigma_b, v_switch, 0.0, d_cos=x[2])

    return jax.vmap(
        lambda ri, vi, ti: jax.jacfwd(lambda x: range_from(ri, vi, ti, x))(jnp.zeros(3))
    )(r, v, t)


@jax.jit
def _switch_partials(problem: NominalProblem, switch, t_sw, sigma_a, sigma_b, v_switch):
    """d(second-entry range)/d(switch speed, flight-path angle, altitude, uniform bank)."""
    earth = problem.model.earth

    def s2(x):
        y = perturb_switch_state(switch, earth, x[0], x[1], x[2])
        return second_entry_range(problem, y, t_sw, sigma_a, sigma_b, v_switch, x[3])

    return jax.jacfwd(s2)(jnp.zeros(4))


def _tracking_sensitivities(problem: NominalProblem, d: DesignResult, rec, node_idx, chute_t):
    """(dR/dN_gx, dR/dḢ, dR/dcos sigma, time to go) at the table nodes ``node_idx``."""
    m = problem.model
    r, v, t, alt, ngx = rec.r, rec.v, rec.t, rec.alt, rec.ngx
    speed, hdot = rec.speed, rec.hdot

    # Range sensitivities along the reference (the gains of the tracking law): at table nodes,
    # d(range)/d(altitude), d(range)/d(flight-path angle) at fixed speed, and d(range)/d(cos
    # sigma) for a uniform change of cos(sigma) from that point on, all by forward-mode autodiff
    # through the remaining second entry.
    sens = np.asarray(
        _node_sensitivities(
            problem, r[node_idx], v[node_idx], t[node_idx], d.sigma_a, d.sigma_b, d.v_switch
        )
    )
    # at fixed speed N_gx is proportional to the density: dN/dh = N dln(rho)/dh
    dlnrho_dh = np.asarray(
        jax.vmap(jax.grad(lambda h: jnp.log(m.atmosphere.density(h))))(jnp.asarray(alt[node_idx]))
    )
    f_drag = sens[:, 0] / (dlnrho_dh * ngx[node_idx])  # m per g of N_gx
    cosg = np.cos(np.arcsin(np.clip(hdot[node_idx] / speed[node_idx], -1, 1)))
    f_hdot = sens[:, 1] / (speed[node_idx] * cosg)  # m per m/s of Ḣ
    f_cos = sens[:, 2]  # m per unit of cos(sigma)
    t_go = chute_t - t[node_idx]

    return f_drag, f_hdot, f_cos, t_go


def tabulate_reference(
    problem: NominalProblem, d: DesignResult, n_grid: int = 256
) -> ReferenceTrajectory:
    """Fly the designed nominal and store the second-entry reference against speed."""
    earth = problem.model.earth
    fl = _fly_nominal(problem, d.sigma_1, d.sigma_a, d.sigma_b, d.v_switch)
    switch, t_sw = fl.switch, fl.t_switch
    rec = _record_second_entry(problem, d, fl)
    n, speed, t, rng = rec.n, rec.speed, rec.t, rec.range_to_go
    chute_t = float(fl.t_chute)
    # range rate: central difference of the range to go along the record
    sdot = np.gradient(rng, t[:n])
    # keep the part where speed decreases monotonically (the table's abscissa)
    keep = np.concatenate([[True], np.diff(speed[:n]) < 0])
    last = int(np.argmin(keep)) if not keep.all() else n
    if last < 3:  # a table needs points; require_design makes this unreachable in practice
        raise ScenarioError(
            f"entry: the designed second entry has {last} tabulable points above the chute "
            "altitude; allowed: an entry whose nominal skips and then descends to the chute"
        )
    grid = np.linspace(speed[0], speed[last - 1], n_grid)
    order = np.argsort(speed[:last])

    def table(x):
        return jnp.asarray(np.interp(grid, speed[:last][order], x[:last][order]))

    node_idx = np.linspace(0, last - 1, 48).astype(int)
    f_drag, f_hdot, f_cos, t_go = _tracking_sensitivities(problem, d, rec, node_idx, chute_t)
    bank, hdot, ngx = rec.bank, rec.hdot, rec.ngx

    def node_table(x):
        o = np.argsort(speed[node_idx])
        return jnp.asarray(np.interp(grid, speed[node_idx][o], x[o]))

    partials = _switch_partials(problem, switch, t_sw, d.sigma_a, d.sigma_b, d.v_switch)
    fv = flight_variables(switch, earth)
    return ReferenceTrajectory(
        velocity_mps=jnp.asarray(grid),
        bank_rad=table(bank),
        range_to_go_m=table(rng),
        hdot_mps=table(hdot),
        drag_load_g=table(ngx),
        range_rate_mps=table(sdot),
        switch_velocity_mps=fv.speed_mps,
        switch_fpa_rad=fv.fpa_rad,
        switch_altitude_m=fv.altitude_m,
        switch_time_s=jnp.asarray(t_sw),
        second_entry_range_m=jnp.asarray(rng[0]),
        d_range_d_switch=partials[:3],
        d_range_d_bank=partials[3],
        first_entry_bank_rad=jnp.asarray(d.sigma_1),
        sigma_a_rad=jnp.asarray(d.sigma_a),
        sigma_b_rad=jnp.asarray(d.sigma_b),
        v_end_mps=jnp.asarray(problem.v_end_mps),
        range_per_drag_load_m=node_table(f_drag),
        range_per_hdot_s=node_table(f_hdot),
        range_per_cos_bank_m=node_table(f_cos),
        time_to_go_s=node_table(t_go),
    )


def cache_dir():
    """Where designed references are kept: ``$GNC_JAX_CACHE`` or ``~/.cache/gnc_jax``."""
    return pathlib.Path(os.environ.get("GNC_JAX_CACHE", pathlib.Path.home() / ".cache" / "gnc_jax"))


_MEMORY: dict = {}


def reference_for(problem: NominalProblem, description: dict, **design_kwargs):
    """The designed reference of ``problem``, designed once and cached.

    ``description`` (JSON-serialisable) identifies the problem; its hash names the cache file
    (``reference-<hash>.npz`` in :func:`cache_dir`, then the packaged copy shipped with
    gnc_jax). It holds the scenario's ``entry`` and ``vehicle`` sections, which the refusals
    quote. A cache miss first refuses a target the design cannot reach
    (:func:`require_reachable`, a few seconds), then runs :func:`design` (about a minute),
    refuses a design that did not converge (:func:`require_design`), tabulates the reference
    (:func:`tabulate_reference`, about 20 s) and saves it. Returns
    ``(ReferenceTrajectory, DesignResult-like dict)``.
    """
    blob = json.dumps(
        {"problem": description, "design": design_kwargs, "version": REFERENCE_VERSION},
        sort_keys=True,
    )
    digest = hashlib.sha256(blob.encode()).hexdigest()[:16]
    if digest in _MEMORY:
        return _MEMORY[digest]
    name = f"reference-{digest}.npz"
    packaged = importlib.resources.files("gnc_jax.guidance.entry") / "references" / name
    path = cache_dir() / name
    source = path if path.is_file() else (packaged if packaged.is_file() else None)
    if source is not None:
        with source.open("rb") as fh:
            data = dict(np.load(fh))
    else:
        entry, vehicle = description["entry"], description["vehicle"]
        print(
            "gnc_jax: designing the reference trajectory of this entry and vehicle (once; the "
            "first design of a process compiles, 1-3 min, later ones take about 10 s; cached in "
            f"{path})",
            file=sys.stderr,
            flush=True,
        )
        steps = design_kwargs.get("steps", 20)
        # stages: the reach check, the optimiser's steps, the tabulation; the first of each
        # compiles, so the bar's rate is only a rough guide
        with tqdm(total=steps + 2, desc="reference design", unit="stage", file=sys.stderr) as bar:
            bar.set_postfix_str("reach check")
            guess = design_kwargs.get("sigma_1_guess")
            _, _, nearest = require_reachable(problem, entry, vehicle, guess)
            bar.update()

            retry = []

            def stepped(step, objective):
                if step == 1 and bar.n > 1:  # design_with_fallback's fine retry: more stages
                    retry.append(True)
                    bar.total += steps
                    bar.refresh()
                label = "fine-step retry, " if retry else ""
                bar.set_postfix_str(f"{label}step {step}/{steps}, objective {objective:.4g}")
                bar.update()

            kwargs = dict(design_kwargs, sigma_1_guess=nearest if guess is None else guess)
            d = design_with_fallback(problem, entry, vehicle, callback=stepped, **kwargs)
            bar.set_postfix_str("tabulating the reference")
            ref = tabulate_reference(problem, d)
            bar.update()
        data = {f: np.asarray(getattr(ref, f)) for f in ReferenceTrajectory.__dataclass_fields__}
        data["objective_history"] = np.asarray(d.objective_history)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez(path, **data)
        except OSError:  # read-only home: keep it in memory only
            pass
    ref = ReferenceTrajectory(
        **{f: jnp.asarray(data[f]) for f in ReferenceTrajectory.__dataclass_fields__}
    )
    info = {"digest": digest, "objective_history": data["objective_history"].tolist()}
    _MEMORY[digest] = (ref, info)
    return ref, info
