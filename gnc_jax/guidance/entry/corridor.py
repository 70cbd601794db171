"""The entry corridor and the reachable footprint of a capsule, by open-loop flight.

What the vehicle can physically do, whatever the guidance: the nominal vehicle flown open loop
with a constant bank angle sigma (lift L cos sigma in the vertical plane, the vertical-plane
dynamics of the predictor: J2 gravity, the scenario's atmosphere) from the entry interface
until it reaches the chute altitude (or the horizon ``simulation.max_time_s`` runs out).

* **Corridor** (in entry flight-path angle): the *overshoot* boundary is the shallowest angle
  at which full lift down (sigma = 180 deg) is still captured, i.e. reaches the chute altitude
  without skipping out; the *undershoot* boundary is the steepest angle at which full lift up
  (sigma = 0) keeps the peak load within the load limit. Outside it no bank history can both
  be captured and respect the load limit: those cells of an envelope are infeasible before
  anything is simulated.
* **Footprint** (in downrange): the chute ranges of the constant-bank flights that land, from
  the shortest (usually full lift down) to the longest (a lofted, lifted skip): the extreme
  ranges of constant-bank profiles. A target inside it and well away from its edges is the
  guidance's business; outside it is physics.

Both are for the nominal vehicle and atmosphere (no dispersion), in the scenario's units.

* **Per-run footprint** (:func:`track_footprints`): the same constant-bank flights and the same
  landing-edge bisection, flown by each Monte Carlo run's own dispersed vehicle, atmosphere
  and entry state, with the chute range measured along the nominal entry -> target track
  (the axis the target's ``range_km`` and the runs' downrange errors are measured on): what
  the dispersed population can physically reach, run by run.
* **Target reach** (:func:`target_crossrange_span`): whether a run can reach the target
  itself, downrange and crossrange: its flights in three dimensions (the lateral lift turns
  them) at constant bank magnitudes reversed once, and the crossrange they land at on the
  target's downrange. The footprint above averages the lateral lift out.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..._types import Array, Scalar
from ...dynamics.entry import (
    EntryConditions,
    EntryState,
    aerodynamic_acceleration,
    entry_state_from_conditions,
    gravity_acceleration,
)
from ...geometry.sphere import along_cross_track, central_angle, destination, to_earth_fixed, unit
from ...integrate import rk4_step
from .base import EntryModel, flight_variables

DT_S = 2.0  # RK4 step of the open-loop flights (the reference design's step)
FOOTPRINT_BANKS_DEG = np.arange(0.0, 180.0 + 1e-9, 5.0)  # the constant banks of the footprint


class OpenLoopFlight(NamedTuple):
    """Outcome of a constant-bank flight: ``landed`` at the chute altitude within the
    horizon, its ``range_m`` (great circle on the rotating Earth from the entry point to the
    chute point), the ``peak_load_g`` (sensed load) flown until then and the chute point
    ``chute_unit`` (Earth-fixed unit vector; the entry point's when it did not land)."""

    landed: Array
    range_m: Scalar
    peak_load_g: Scalar
    chute_unit: Array


def banked_field(model: EntryModel):
    """d/dt (r, v) of ``model`` in three dimensions at a signed bank (rad, the argument): the
    lift's lateral component turns the flight (negative bank: to the left), as the truth
    flies it."""
    vehicle = model.measured_vehicle()

    def field(t, y: EntryState, bank) -> EntryState:
        del t
        a = gravity_acceleration(y.r, model.earth) + aerodynamic_acceleration(
            y.r, y.v, bank, vehicle, model.earth, model.atmosphere
        )
        return EntryState(y.v, a)

    return field


def fly_from_state(
    model: EntryModel,
    y0: EntryState,
    bank_rad: Scalar,
    chute_m: Scalar,
    steps: int,
    lateral: bool = False,
    reversal_s: Scalar = jnp.inf,
) -> OpenLoopFlight:
    """One open-loop flight of ``steps`` RK4 steps of ``DT_S`` (s) at constant bank (rad) from
    the ECI state ``y0`` at t = 0 (m, m/s) to the chute altitude ``chute_m`` (m; the state
    freezes there). ``lateral`` (static): fly the signed bank in three dimensions
    (:func:`banked_field`), reversed once at ``reversal_s`` (s; never by default), instead of
    the vertical plane (lift L cos sigma)."""
    earth = model.earth
    if lateral:
        field = banked_field(model)
        arg_at = lambda t: jnp.where(t < reversal_s, bank_rad, -bank_rad)  # noqa: E731
    else:
        cos_b = jnp.cos(bank_rad)
        field = lambda t, y, a: model.vertical_plane_field(t, y, a)  # noqa: E731
        arg_at = lambda t: cos_b  # noqa: E731

    def body(c, _):
        y, t, done, peak, chute_r, t_chute = c
        y1 = rk4_step(field, t, y, DT_S, arg_at(t))
        alt1 = flight_variables(y1, earth).altitude_m
        crossing = ~done & (alt1 < chute_m)
        peak = jnp.where(done, peak, jnp.maximum(peak, model.load_g(y1)))
        chute_r = jnp.where(crossing, y1.r, chute_r)
        t_chute = jnp.where(crossing, t + DT_S, t_chute)
        y = jax.tree_util.tree_map(lambda a, b: jnp.where(done, a, b), y, y1)
        return (y, t + DT_S, done | crossing, peak, chute_r, t_chute), None

    z = jnp.zeros(())
    init = (y0, z, jnp.asarray(False), model.load_g(y0), y0.r, z)
    (_, _, done, peak, chute_r, t_chute), _ = jax.lax.scan(body, init, None, length=steps)
    u0 = unit(to_earth_fixed(y0.r, 0.0, earth.rotation_rate))
    u1 = unit(to_earth_fixed(chute_r, t_chute, earth.rotation_rate))
    return OpenLoopFlight(done, earth.equatorial_radius_m * central_angle(u0, u1), peak, u1)


def fly_constant_bank(
    model: EntryModel, entry: EntryConditions, bank_rad: Scalar, chute_m: Scalar, steps: int
) -> OpenLoopFlight:
    """One open-loop flight of ``steps`` RK4 steps of ``DT_S`` at constant bank (rad), from
    the entry interface to the chute altitude ``chute_m`` (the state freezes there)."""
    y0 = entry_state_from_conditions(entry, model.earth)
    return fly_from_state(model, y0, bank_rad, chute_m, steps)


def _with_fpa(entry: EntryConditions, fpa_rad) -> EntryConditions:
    return entry._replace(flight_path_angle=jnp.asarray(fpa_rad, dtype=jnp.float64))


def _flights(model, entry, fpas_rad, banks_rad, chute_m, steps):
    """Flights for every (entry angle, bank) pair: arrays of shape (fpas, banks)."""

    def one(fpa, bank):
        return fly_constant_bank(model, _with_fpa(entry, fpa), bank, chute_m, steps)

    return jax.vmap(lambda f: jax.vmap(lambda b: one(f, b))(banks_rad))(fpas_rad)


_flights_jit = jax.jit(_flights, static_argnames=("steps",))


def _bisect_edge(model, y0, out_rad, in_rad, chute_m, steps) -> OpenLoopFlight:
    """Bisection (30 halvings) of the bank between ``out_rad`` (does not land) and ``in_rad``
    (lands) from the state ``y0``; the flight at the landing side of the edge."""

    def halve(_, ends):
        o, i = ends
        mid = 0.5 * (o + i)
        lands = fly_from_state(model, y0, mid, chute_m, steps).landed
        return jnp.where(lands, o, mid), jnp.where(lands, mid, i)

    _, inside = jax.lax.fori_loop(0, 30, halve, (out_rad, in_rad))
    return fly_from_state(model, y0, inside, chute_m, steps)


@jax.jit(static_argnames=("steps",))
def _landing_edge(model, entry, fpas_rad, out_rad, in_rad, chute_m, steps):
    """:func:`_bisect_edge` for each entry angle."""

    def one(fpa, out, inside):
        y0 = entry_state_from_conditions(_with_fpa(entry, fpa), model.earth)
        return _bisect_edge(model, y0, out, inside, chute_m, steps)

    return jax.vmap(one)(fpas_rad, out_rad, in_rad)


def track_range_m(chute_unit: Array, start_unit: Array, azimuth: Scalar, earth) -> Scalar:
    """Range (m) of a point along a track: the great circle leaving ``start_unit`` (Earth-fixed
    unit vector) at ``azimuth`` (rad clockwise from north), measured from the start to the
    point's foot on the track (its crossrange dropped), in (-pi/2, 3pi/2) x R_e. On the nominal
    entry -> target track this is the axis of the target's ``entry.range_km``: a chute point at
    the target's range has zero downrange error."""
    quarter = destination(start_unit, azimuth, jnp.pi / 2)
    along = along_cross_track(chute_unit, start_unit, quarter)[0]
    return earth.equatorial_radius_m * (along + jnp.pi / 2)


def track_footprint(
    model: EntryModel, y0: EntryState, start_unit, azimuth, chute_m, steps: int
) -> Array:
    """[shortest, longest] chute range (m) along the track from ``start_unit`` at ``azimuth``
    (:func:`track_range_m`) of the constant-bank flights (``FOOTPRINT_BANKS_DEG``) of
    ``model`` from ``y0`` that land, the longest including the landing-edge bisection of
    :meth:`EntryEnvelope.footprints` (between the highest-lift bank that does not land and the
    next, when a lower bank does not land); NaN, NaN when no bank lands (a skip-out even with
    full lift down)."""
    banks = jnp.radians(jnp.asarray(FOOTPRINT_BANKS_DEG))
    f = jax.vmap(lambda b: fly_from_state(model, y0, b, chute_m, steps))(banks)
    rng = jax.vmap(lambda u: track_range_m(u, start_unit, azimuth, model.earth))(f.chute_unit)
    k = jnp.argmax(f.landed)  # the lowest landing bank (lift-up side)
    any_lands = f.landed.any()
    edge = any_lands & (k > 0)
    e = _bisect_edge(model, y0, banks[jnp.maximum(k - 1, 0)], banks[k], chute_m, steps)
    e_rng = track_range_m(e.chute_unit, start_unit, azimuth, model.earth)
    lo = jnp.min(jnp.where(f.landed, rng, jnp.inf))
    hi = jnp.max(jnp.where(f.landed, rng, -jnp.inf))
    hi = jnp.where(edge & e.landed, jnp.maximum(hi, e_rng), hi)
    return jnp.where(any_lands, jnp.stack([lo, hi]), jnp.nan)


@jax.jit(static_argnames=("steps",))
def track_footprints(models: EntryModel, y0s: EntryState, start_unit, azimuth, chute_m, steps):
    """:func:`track_footprint` of a batch of models and states (leading axis of every leaf),
    shape (n, 2), m."""
    return jax.vmap(lambda m, y: track_footprint(m, y, start_unit, azimuth, chute_m, steps))(
        models, y0s
    )


REACH_BANKS_DEG = np.arange(0.0, 180.0 + 1e-9, 5.0)  # bank magnitudes of the target reach
# times (s) of the one reversal of the target reach's flights, the last none (a one-sided
# flight): the first entry's, where the heading that the Kepler arc carries is set
REACH_REVERSALS_S = np.append(np.arange(0.0, 400.0, 10.0), np.inf)


def _span_of(hit, cross):
    lo = jnp.min(jnp.where(hit, cross, jnp.inf))
    hi = jnp.max(jnp.where(hit, cross, -jnp.inf))
    return jnp.where(hit.any(), jnp.stack([lo, hi]), jnp.nan)


def grid_crossings(landed, along, cross):
    """Crossranges at zero along-track error along the last axis (magnitudes): wherever the
    along error changes sign between neighbouring magnitudes that both land, interpolated
    linearly; ``(hit, crossrange)`` of the neighbouring pairs."""
    a0, a1 = along[..., :-1], along[..., 1:]
    hit = landed[..., :-1] & landed[..., 1:] & (a0 * a1 <= 0.0) & (a0 != a1)
    w = a0 / jnp.where(a0 != a1, a0 - a1, 1.0)
    return hit, cross[..., :-1] + w * (cross[..., 1:] - cross[..., :-1])


def _family_crossings(fly, banks, track):
    """The zero along-track crossings of one family of magnitudes (``fly(bank)`` a flight,
    ``track(unit)`` its (along, cross) angles): those of the grid (:func:`grid_crossings`)
    and, as the footprint's longest range, the one between the landing edge (bisected, 30
    halvings, as :func:`_bisect_edge`) and the lowest landing magnitude, found by 30
    halvings of the along error; ``(hit, crossrange)``."""
    f = jax.vmap(fly)(banks)
    ac = jax.vmap(track)(f.chute_unit)
    hit, cross = grid_crossings(f.landed, ac[:, 0], ac[:, 1])
    k = jnp.argmax(f.landed)

    def halve_edge(_, ends):
        o, i = ends
        mid = 0.5 * (o + i)
        lands = fly(mid).landed
        return jnp.where(lands, o, mid), jnp.where(lands, mid, i)

    _, edge = jax.lax.fori_loop(0, 30, halve_edge, (banks[jnp.maximum(k - 1, 0)], banks[k]))
    a_edge = track(fly(edge).chute_unit)[0]
    a_k = ac[k, 0]

    def halve_along(_, ends):
        e, b = ends
        mid = 0.5 * (e + b)
        same = track(fly(mid).chute_unit)[0] * a_edge > 0.0
        return jnp.where(same, mid, e), jnp.where(same, b, mid)

    lo, hi = jax.lax.fori_loop(0, 30, halve_along, (edge, banks[k]))
    last = fly(0.5 * (lo + hi))
    beyond = (k > 0) & f.landed.any() & (a_edge * a_k < 0.0) & last.landed
    return (
        jnp.append(hit, beyond),
        jnp.append(cross, track(last.chute_unit)[1]),
    )


@jax.jit(static_argnames=("steps",))
def target_crossrange_span(
    model: EntryModel, y0: EntryState, start_unit, target_unit, chute_m, steps
):
    """[least, greatest] crossrange (m; > 0 left of the ``start_unit`` -> ``target_unit``
    track) at the target's downrange of the three-dimensional constant-magnitude flights of
    ``model`` from ``y0`` (:func:`fly_from_state` with ``lateral``): each magnitude of
    ``REACH_BANKS_DEG`` flown right (+) or left (-) first and reversed once at each time
    of ``REACH_REVERSALS_S``, the crossings of each family by :func:`_family_crossings`.
    The crossrange moves continuously with the reversal time, so the run reaches the
    target, downrange and crossrange, when the span holds 0 (with a bank of one magnitude
    reversed once; a bank history the law flies may reach a little more); NaN, NaN when no
    flight lands at the target's downrange."""
    banks = jnp.radians(jnp.asarray(REACH_BANKS_DEG))
    track = lambda u: along_cross_track(u, start_unit, target_unit)  # noqa: E731

    def family(sign, tau):
        fly = lambda b: fly_from_state(model, y0, sign * b, chute_m, steps, True, tau)  # noqa: E731
        return _family_crossings(fly, banks, track)

    times = jnp.asarray(REACH_REVERSALS_S)
    hit, cross = jax.vmap(lambda s: jax.vmap(lambda tau: family(s, tau))(times))(
        jnp.array([1.0, -1.0])
    )
    return model.earth.equatorial_radius_m * _span_of(hit, cross)


class Corridor(NamedTuple):
    """Entry flight-path angles (deg): ``overshoot_deg`` the shallowest captured with full lift
    down, ``undershoot_deg`` the steepest within the load limit with full lift up (NaN when no
    angle of the search interval qualifies)."""

    overshoot_deg: float
    undershoot_deg: float
    load_limit_g: float

    def contains(self, fpa_deg: float) -> bool:
        return bool(self.undershoot_deg <= fpa_deg <= self.overshoot_deg)


def _boundary(ok: np.ndarray, grid: np.ndarray, which: str) -> float:
    """The edge of ``grid`` where ``ok`` holds: the largest (``which = "max"``) or smallest
    angle with ``ok``; NaN when none."""
    if not ok.any():
        return math.nan
    return float(grid[ok].max() if which == "max" else grid[ok].min())


class EntryEnvelope:
    """Corridor and footprint of one vehicle, atmosphere and entry (all but the angle).

    Args:
        model, entry: the nominal :class:`EntryModel` and entry interface (SI).
        chute_m: chute altitude; horizon_s: the longest flight (``simulation.max_time_s``).
        load_limit_g: the undershoot boundary's load limit.
    """

    def __init__(self, model, entry, chute_m, horizon_s, load_limit_g):
        self.model, self.entry, self.chute_m = model, entry, float(chute_m)
        self.steps = int(math.ceil(horizon_s / DT_S))
        self.load_limit_g = float(load_limit_g)

    def flights(self, fpas_deg, banks_deg) -> OpenLoopFlight:
        out = _flights_jit(
            self.model,
            self.entry,
            jnp.radians(jnp.asarray(fpas_deg, dtype=jnp.float64)),
            jnp.radians(jnp.asarray(banks_deg, dtype=jnp.float64)),
            self.chute_m,
            self.steps,
        )
        return OpenLoopFlight(*(np.asarray(x) for x in out))

    def feasible(self, fpa_deg: float) -> tuple[bool, str]:
        """The corridor pre-check of one entry angle, and why not."""
        f = self.flights([fpa_deg], [180.0, 0.0])
        captured = bool(f.landed[0, 0])
        load_up = float(f.peak_load_g[0, 1])
        if not captured:
            return False, f"overshoot: skips out with full lift down at {fpa_deg:g} deg"
        if load_up > self.load_limit_g:
            return False, (
                f"undershoot: {load_up:.3g} g with full lift up at {fpa_deg:g} deg, above the "
                f"{self.load_limit_g:g} g limit"
            )
        return True, ""

    def corridor(self, lo_deg: float, hi_deg: float, step_deg: float = 0.05) -> Corridor:
        """The corridor on a grid of ``step_deg`` over [lo_deg, hi_deg] (deg)."""
        grid = np.arange(lo_deg, hi_deg + 1e-9, step_deg)
        f = self.flights(grid, [180.0, 0.0])
        captured = f.landed[:, 0]
        within = f.peak_load_g[:, 1] <= self.load_limit_g
        return Corridor(
            _boundary(captured, grid, "max"), _boundary(within, grid, "min"), self.load_limit_g
        )

    def footprints(self, fpas_deg) -> np.ndarray:
        """Shortest and longest chute range (km) of the constant-bank flights that land, for
        each entry angle: shape (n, 2), NaN where none lands.

        Banks ``FOOTPRINT_BANKS_DEG`` (every 5 deg), then, where a lower bank no longer lands
        within the horizon (the lofted skip grows without bound as lift rises: the range is
        continuous up to there), the bank is bisected to that edge and its range taken: the
        longest constant-bank range is there, not on the 5 deg grid.
        """
        fpas = np.atleast_1d(np.asarray(fpas_deg, dtype=float))
        f = self.flights(fpas, FOOTPRINT_BANKS_DEG)
        out = np.full((len(fpas), 2), np.nan)
        banks = np.radians(FOOTPRINT_BANKS_DEG)
        k = np.argmax(f.landed, axis=1)  # the lowest landing bank (lift up side)
        edge = f.landed.any(axis=1) & (k > 0)
        extra = np.full(len(fpas), np.nan)
        if edge.any():
            e = _landing_edge(
                self.model,
                self.entry,
                jnp.radians(jnp.asarray(fpas[edge])),
                jnp.asarray(banks[k[edge] - 1]),
                jnp.asarray(banks[k[edge]]),
                self.chute_m,
                self.steps,
            )
            extra[edge] = np.where(np.asarray(e.landed), np.asarray(e.range_m) / 1e3, np.nan)
        for i in range(len(fpas)):
            r = f.range_m[i][f.landed[i]] / 1e3
            if r.size:
                out[i] = [r.min(), np.nanmax(np.append(r, extra[i]))]
        return out

    def footprint(self, fpa_deg: float) -> tuple[float, float]:
        """:meth:`footprints` of one entry angle."""
        lo, hi = self.footprints([fpa_deg])[0]
        return float(lo), float(hi)


__all__ = [
    "OpenLoopFlight",
    "fly_constant_bank",
    "fly_from_state",
    "track_range_m",
    "track_footprint",
    "track_footprints",
    "Corridor",
    "EntryEnvelope",
]
