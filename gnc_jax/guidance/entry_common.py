"""Pieces shared by the capsule's on-board predictor and its offline reference design.

Both fly the longitudinal ("vertical-plane") problem: lift acts in the vertical plane with the
magnitude L cos(sigma), i.e. the lateral component of a banked lift vector is averaged out by
the bank reversals. The bank magnitude follows a profile of Earth-relative speed.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._types import Scalar, Vector3
from ..dynamics.atmosphere import Atmosphere
from ..dynamics.entry import (
    G0,
    EarthModel,
    EntryState,
    EntryVehicle,
    aerodynamic_acceleration,
    altitude,
    earth_relative_velocity,
    gravity_acceleration,
    sensed_load_g,
)
from ..geometry.sphere import central_angle, to_earth_fixed, unit


class EntryModel(eqx.Module):
    """On-board model of the capsule: vehicle, Earth, atmosphere, and the measured ratios of
    actual to modelled drag and lift (1 for the nominal model)."""

    vehicle: EntryVehicle
    earth: EarthModel
    atmosphere: Atmosphere
    drag_ratio: Scalar = eqx.field(default=1.0, converter=jnp.asarray)
    lift_ratio: Scalar = eqx.field(default=1.0, converter=jnp.asarray)

    def scaled_vehicle(self, cos_bank) -> EntryVehicle:
        """Vehicle whose 'lift-up' lift equals the vertical component L cos(sigma)."""
        v = self.vehicle
        return eqx.tree_at(
            lambda x: (x.lift_scale, x.drag_scale),
            v,
            (v.lift_scale * self.lift_ratio * cos_bank, v.drag_scale * self.drag_ratio),
        )

    def vertical_plane_field(self, t, y: EntryState, cos_bank) -> EntryState:
        """d/dt (r, v) with lift L cos(sigma) in the vertical plane."""
        vehicle = self.scaled_vehicle(cos_bank)
        a = gravity_acceleration(y.r, self.earth) + aerodynamic_acceleration(
            y.r, y.v, 0.0, vehicle, self.earth, self.atmosphere
        )
        return EntryState(y.v, a)

    def load_g(self, y: EntryState) -> Scalar:
        """Sensed load N_g (g) under the model's drag and lift ratios."""
        vehicle = eqx.tree_at(
            lambda x: (x.lift_scale, x.drag_scale),
            self.vehicle,
            (self.vehicle.lift_scale * self.lift_ratio, self.vehicle.drag_scale * self.drag_ratio),
        )
        return sensed_load_g(y.r, y.v, vehicle, self.earth, self.atmosphere)


class FlightVariables(NamedTuple):
    """Longitudinal variables of the guidance (seed 003 §2-3), Earth-relative."""

    speed_mps: Scalar
    fpa_rad: Scalar
    altitude_m: Scalar
    hdot_mps: Scalar


def flight_variables(y: EntryState, earth: EarthModel) -> FlightVariables:
    v_rel = earth_relative_velocity(y.r, y.v, earth)
    speed = jnp.linalg.norm(v_rel)
    hdot = jnp.dot(unit(y.r), v_rel)
    return FlightVariables(
        speed, jnp.arcsin(jnp.clip(hdot / speed, -1, 1)), altitude(y.r, earth), hdot
    )


def drag_load_g(y: EntryState, model: EntryModel) -> Scalar:
    """Tangential (drag) load N_gx = D / (m g0), g."""
    v = model.vehicle
    v_rel = earth_relative_velocity(y.r, y.v, model.earth)
    rho = model.atmosphere.density(altitude(y.r, model.earth))
    q = 0.5 * rho * jnp.dot(v_rel, v_rel)
    return q * v.reference_area_m2 * v.c_d * model.drag_ratio / (v.mass_kg * G0)


def perturb_switch_state(
    y: EntryState, earth: EarthModel, d_speed, d_fpa, d_altitude
) -> EntryState:
    """Shift a state's Earth-relative speed (m/s), flight-path angle (rad) and altitude (m),
    keeping its position on the ground and its heading: the variables of seed 003 eq. 10."""
    r_hat = unit(y.r)
    v_rel = earth_relative_velocity(y.r, y.v, earth)
    speed = jnp.linalg.norm(v_rel)
    hdot = jnp.dot(r_hat, v_rel)
    fpa = jnp.arcsin(jnp.clip(hdot / speed, -1.0, 1.0))
    horizontal = unit(v_rel - hdot * r_hat)
    new_speed, new_fpa = speed + d_speed, fpa + d_fpa
    r = y.r + d_altitude * r_hat
    v_rel_new = new_speed * (jnp.cos(new_fpa) * horizontal + jnp.sin(new_fpa) * r_hat)
    return EntryState(r, v_rel_new + jnp.cross(earth.angular_velocity(), r))


def ground_range_m(r1: Vector3, t1, r2: Vector3, t2, earth: EarthModel) -> Scalar:
    """Great-circle distance over the rotating Earth between two ECI points at two times, m."""
    u1 = unit(to_earth_fixed(r1, t1, earth.rotation_rate))
    u2 = unit(to_earth_fixed(r2, t2, earth.rotation_rate))
    return earth.equatorial_radius_m * central_angle(u1, u2)


def hermite_crossing(f0, df0, f1, df1, dt, level):
    """Fraction s in [0, 1] of a step at which a cubic Hermite interpolant of f crosses
    ``level`` (f0 above, f1 below it), found by a few Newton steps from the linear guess."""
    s = jnp.clip((f0 - level) / jnp.where(f0 != f1, f0 - f1, 1.0), 0.0, 1.0)

    def newton(_, s):
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = s**3 - 2 * s**2 + s
        h01 = -2 * s**3 + 3 * s**2
        h11 = s**3 - s**2
        f = h00 * f0 + h10 * dt * df0 + h01 * f1 + h11 * dt * df1 - level
        d = (
            (6 * s**2 - 6 * s) * f0
            + (3 * s**2 - 4 * s + 1) * dt * df0
            + (-6 * s**2 + 6 * s) * f1
            + (3 * s**2 - 2 * s) * dt * df1
        )
        return jnp.clip(s - f / jnp.where(d != 0, d, 1.0), 0.0, 1.0)

    return jax.lax.fori_loop(0, 4, newton, s)


def hermite_state(y0: EntryState, a0, y1: EntryState, a1, dt, s) -> EntryState:
    """Cubic Hermite interpolation of (r, v) at fraction s of a step of length dt, using the
    accelerations a0, a1 at both ends for v and the velocities for r."""
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    r = h00 * y0.r + h10 * dt * y0.v + h01 * y1.r + h11 * dt * y1.v
    v = h00 * y0.v + h10 * dt * a0 + h01 * y1.v + h11 * dt * a1
    return EntryState(r, v)
