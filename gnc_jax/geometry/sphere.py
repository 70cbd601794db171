"""Great-circle geometry on the spherical Earth, in Cartesian form (no haversine round-off).

Points are unit vectors; angles between them use ``atan2(|u1 x u2|, u1 . u2)``, which is
accurate at every separation (``acos`` loses half the digits near 0 and pi).
"""

import jax.numpy as jnp

from .._types import Array, Float, Scalar, Vector3


def unit(x: Vector3) -> Vector3:
    """x / |x| (a zero vector gives zeros, with finite gradients)."""
    n2 = jnp.dot(x, x)
    ok = n2 > 0.0
    return jnp.where(ok, x / jnp.sqrt(jnp.where(ok, n2, 1.0)), 0.0)


def central_angle(u1: Vector3, u2: Vector3) -> Scalar:
    """Great-circle angle between two directions, rad, in [0, pi]."""
    c = jnp.cross(u1, u2)
    n2 = jnp.dot(c, c)
    # |u1 x u2| with a finite gradient when the points coincide
    s = jnp.where(n2 > 0.0, jnp.sqrt(jnp.where(n2 > 0.0, n2, 1.0)), 0.0)
    return jnp.arctan2(s, jnp.dot(u1, u2))


def rotate_z(x: Vector3, angle) -> Vector3:
    """Rotate ``x`` by ``angle`` (rad) about the z axis."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.array([c * x[0] - s * x[1], s * x[0] + c * x[1], x[2]])


def to_earth_fixed(r_eci: Vector3, t, rotation_rate) -> Vector3:
    """ECI -> Earth-fixed (the frames coincide at t = 0)."""
    return rotate_z(r_eci, -rotation_rate * t)


def to_inertial(r_fixed: Vector3, t, rotation_rate) -> Vector3:
    """Earth-fixed -> ECI."""
    return rotate_z(r_fixed, rotation_rate * t)


def destination(start: Vector3, azimuth, angle) -> Vector3:
    """Point reached from the unit vector ``start`` along a great circle.

    Args:
        start: starting point (unit vector).
        azimuth: initial heading, rad clockwise from north.
        angle: great-circle angle travelled, rad.
    """
    z = jnp.array([0.0, 0.0, 1.0])
    east = unit(jnp.cross(z, start))
    north = jnp.cross(start, east)
    heading = jnp.cos(azimuth) * north + jnp.sin(azimuth) * east
    return jnp.cos(angle) * start + jnp.sin(angle) * heading


def along_cross_track(point: Vector3, start: Vector3, target: Vector3) -> Float[Array, "2"]:
    """(along, cross) angles (rad) of ``point`` relative to ``target`` on the great circle
    from ``start`` to ``target``.

    along > 0: beyond the target (overshoot); cross > 0: to the left of the start -> target
    direction of travel.
    """
    n = unit(jnp.cross(start, target))
    cross = jnp.arcsin(jnp.clip(jnp.dot(point, n), -1.0, 1.0))
    p = point - jnp.dot(point, n) * n
    along = jnp.arctan2(jnp.dot(jnp.cross(target, p), n), jnp.dot(target, p))
    return jnp.stack([along, cross])


def crossrange_to_target(r: Vector3, v_rel: Vector3, target: Vector3) -> Scalar:
    """Angle (rad) of the target off the current great circle of motion; > 0: target on the
    left of the velocity (a left turn, negative bank, closes it)."""
    h = unit(jnp.cross(r, v_rel))
    return jnp.arcsin(jnp.clip(jnp.dot(target, h), -1.0, 1.0))


def range_rate_to_target(r: Vector3, v_rel: Vector3, target: Vector3) -> Scalar:
    """d/dt of the great-circle angle to an Earth-fixed target, rad/s (< 0 when closing).

    ``v_rel`` is the Earth-relative velocity.
    """
    u = unit(r)
    toward = unit(target - jnp.dot(target, u) * u)
    return -jnp.dot(v_rel, toward) / jnp.linalg.norm(r)


def along_track_to_go(r: Vector3, v_rel: Vector3, target: Vector3) -> Scalar:
    """Angle (rad) to the target's abeam point on the current great circle of motion, > 0
    while the target is ahead: the range to go without its crossrange part."""
    u = unit(r)
    h = unit(jnp.cross(r, v_rel))
    p = target - jnp.dot(target, h) * h
    return jnp.arctan2(jnp.dot(jnp.cross(u, p), h), jnp.dot(u, p))
