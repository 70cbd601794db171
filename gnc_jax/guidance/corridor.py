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
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._types import Array, Scalar
from ..dynamics.entry import EntryConditions, entry_state_from_conditions
from ..geometry.sphere import central_angle, to_earth_fixed, unit
from ..integrate import rk4_step
from .entry_common import EntryModel, flight_variables

DT_S = 2.0  # RK4 step of the open-loop flights (the reference design's step)
FOOTPRINT_BANKS_DEG = np.arange(0.0, 180.0 + 1e-9, 5.0)  # the constant banks of the footprint


class OpenLoopFlight(NamedTuple):
    """Outcome of a constant-bank flight: ``landed`` at the chute altitude within the
    horizon, its ``range_m`` (great circle on the rotating Earth from the entry point to the
    chute point) and the ``peak_load_g`` (sensed load) flown until then."""

    landed: Array
    range_m: Scalar
    peak_load_g: Scalar


def fly_constant_bank(
    model: EntryModel, entry: EntryConditions, bank_rad: Scalar, chute_m: Scalar, steps: int
) -> OpenLoopFlight:
    """One open-loop flight of ``steps`` RK4 steps of ``DT_S`` at constant bank (rad), from
    the entry interface to the chute altitude ``chute_m`` (the state freezes there)."""
    earth = model.earth
    y0 = entry_state_from_conditions(entry, earth)
    cos_b = jnp.cos(bank_rad)
    field = lambda t, y, a: model.vertical_plane_field(t, y, a)  # noqa: E731

    def body(c, _):
        y, t, done, peak, chute_r, t_chute = c
        y1 = rk4_step(field, t, y, DT_S, cos_b)
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
    return OpenLoopFlight(done, earth.equatorial_radius_m * central_angle(u0, u1), peak)


def _with_fpa(entry: EntryConditions, fpa_rad) -> EntryConditions:
    return entry._replace(flight_path_angle=jnp.asarray(fpa_rad, dtype=jnp.float64))


def _flights(model, entry, fpas_rad, banks_rad, chute_m, steps):
    """Flights for every (entry angle, bank) pair: arrays of shape (fpas, banks)."""

    def one(fpa, bank):
        return fly_constant_bank(model, _with_fpa(entry, fpa), bank, chute_m, steps)

    return jax.vmap(lambda f: jax.vmap(lambda b: one(f, b))(banks_rad))(fpas_rad)


_flights_jit = jax.jit(_flights, static_argnames=("steps",))


@jax.jit(static_argnames=("steps",))
def _landing_edge(model, entry, fpas_rad, out_rad, in_rad, chute_m, steps):
    """Bisection (30 halvings) of the bank between ``out_rad`` (does not land) and ``in_rad``
    (lands) for each entry angle; the flight at the landing side of the edge."""

    def one(fpa, out, inside):
        e = _with_fpa(entry, fpa)

        def halve(_, ends):
            o, i = ends
            mid = 0.5 * (o + i)
            lands = fly_constant_bank(model, e, mid, chute_m, steps).landed
            return jnp.where(lands, o, mid), jnp.where(lands, mid, i)

        _, inside = jax.lax.fori_loop(0, 30, halve, (out, inside))
        return fly_constant_bank(model, e, inside, chute_m, steps)

    return jax.vmap(one)(fpas_rad, out_rad, in_rad)


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


__all__ = ["OpenLoopFlight", "fly_constant_bank", "Corridor", "EntryEnvelope"]
