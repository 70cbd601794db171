"""Where the capsule is in Earth-relative terms: altitude, Earth-relative velocity,
flight-path angle, latitude and longitude, and entry conditions to and from the ECI state."""

import jax.numpy as jnp

from ..._types import Array, Float, Scalar, Vector3
from .models import EarthModel
from .state import EntryConditions, EntryState
from .vectors import _unit


def altitude(r: Vector3, earth: EarthModel) -> Scalar:
    """Altitude above the spherical Earth, |r| - R_E, m."""
    return jnp.linalg.norm(r) - earth.equatorial_radius_m


def earth_relative_velocity(r: Vector3, v: Vector3, earth: EarthModel) -> Vector3:
    """Velocity relative to the rotating Earth and its air, v - omega_E x r, ECI axes, m/s."""
    return v - jnp.cross(earth.angular_velocity(), r)


def flight_path_angle(r: Vector3, v: Vector3) -> Scalar:
    """Angle of ``v`` above the local horizontal, asin(r_hat . v_hat), rad.

    Pass `earth_relative_velocity` for the Earth-relative angle, ``v`` for the inertial one.
    """
    return jnp.arcsin(jnp.clip(jnp.dot(_unit(r), _unit(v)), -1.0, 1.0))


def geocentric_latitude_longitude(
    r: Vector3, t: Scalar, earth: EarthModel
) -> tuple[Scalar, Scalar]:
    """Geocentric latitude and east longitude (rad) of ECI position ``r`` at time ``t`` (s).

    Longitude = atan2(y, x) - omega_E t, wrapped to (-pi, pi]. The model Earth is a sphere, so
    geocentric latitude is the one that enters gravity (seed 003 eq. 3) and the entry point.
    """
    latitude = jnp.arcsin(jnp.clip(r[2] / jnp.linalg.norm(r), -1.0, 1.0))
    longitude = jnp.arctan2(r[1], r[0]) - earth.rotation_rate * t
    longitude = jnp.arctan2(jnp.sin(longitude), jnp.cos(longitude))
    return latitude, longitude


def _east_north_up(latitude: Scalar, longitude: Scalar) -> tuple[Vector3, Vector3, Vector3]:
    """Local east, north, up unit vectors in the Earth-fixed frame."""
    sl, cl = jnp.sin(latitude), jnp.cos(latitude)
    so, co = jnp.sin(longitude), jnp.cos(longitude)
    east = jnp.array([-so, co, 0.0])
    north = jnp.array([-sl * co, -sl * so, cl])
    up = jnp.array([cl * co, cl * so, sl])
    return east, north, up


def _rotation_about_z(angle: Scalar) -> Float[Array, "3 3"]:
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def entry_state_from_conditions(
    conditions: EntryConditions, earth: EarthModel, t: Scalar = 0.0
) -> EntryState:
    """ECI state at time ``t`` (s) from Earth-relative entry conditions.

    r = (R_E + h) u;  v_rel = V (cos gamma sin psi e + cos gamma cos psi n + sin gamma u)
    in the local east-north-up frame, rotated by omega_E t into ECI; v = v_rel + omega_E x r.
    """
    c = conditions
    east, north, up = _east_north_up(c.latitude, c.longitude)
    v_rel_fixed = c.speed_mps * (
        jnp.cos(c.flight_path_angle) * (jnp.sin(c.azimuth) * east + jnp.cos(c.azimuth) * north)
        + jnp.sin(c.flight_path_angle) * up
    )
    to_eci = _rotation_about_z(earth.rotation_rate * t)
    r = to_eci @ ((earth.equatorial_radius_m + c.altitude_m) * up)
    v = to_eci @ v_rel_fixed + jnp.cross(earth.angular_velocity(), r)
    return EntryState(r, v)


def entry_conditions_from_state(
    state: EntryState, earth: EarthModel, t: Scalar = 0.0
) -> EntryConditions:
    """Earth-relative entry conditions of an ECI state at time ``t`` (s); inverse of
    `entry_state_from_conditions`."""
    r, v = state
    latitude, longitude = geocentric_latitude_longitude(r, t, earth)
    v_rel = earth_relative_velocity(r, v, earth)
    # Local frame in ECI axes: the Earth-fixed one at the inertial longitude of r.
    east, north, up = _east_north_up(latitude, jnp.arctan2(r[1], r[0]))
    return EntryConditions(
        altitude_m=altitude(r, earth),
        speed_mps=jnp.linalg.norm(v_rel),
        flight_path_angle=flight_path_angle(r, v_rel),
        azimuth=jnp.arctan2(jnp.dot(v_rel, east), jnp.dot(v_rel, north)),
        longitude=longitude,
        latitude=latitude,
    )
