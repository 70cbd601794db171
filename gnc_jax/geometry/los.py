"""Line-of-sight kinematics (seed 000 §1.2 and §3.2, eqs. 3, 7, 21, 22).

``rho`` is the vector from the impactor to the aim point and ``rho_dot`` its time derivative.
"""

import jax.numpy as jnp

from .._numerics import cross3, dot3, norm3
from .._types import Matrix3, Scalar, Vector3


def los_frame(rho: Vector3, r_axis: Vector3) -> Matrix3:
    """Non-rolling LOS frame (seed 000 eq. 3): rows xi, eta, zeta in the input frame.

    xi = rho/|rho|, zeta = xi x R / |xi x R|, eta = zeta x xi, with R the B-plane R axis.
    """
    xi = rho / jnp.linalg.norm(rho)
    zeta = jnp.cross(xi, r_axis)
    zeta = zeta / jnp.linalg.norm(zeta)
    eta = jnp.cross(zeta, xi)
    return jnp.stack([xi, eta, zeta])


def los_rate(rho: Vector3, rho_dot: Vector3) -> Vector3:
    """LOS angular-rate vector omega = rho x rho_dot / rho^2 (seed 000 eq. 21), rad/s."""
    return cross3(rho, rho_dot) / dot3(rho, rho)


def range_rate(rho: Vector3, rho_dot: Vector3) -> Scalar:
    """Range rate rho_dot = rho . rho_dot / |rho| (seed 000 eq. 22), m/s (negative closing)."""
    return dot3(rho, rho_dot) / norm3(rho)


def unforced_miss(rho: Vector3, rho_dot: Vector3) -> Scalar:
    """Unforced miss distance (seed 000 eq. 7), m.

    rho_f = rho0^2 omega0 / sqrt(rho_dot0^2 + rho0^2 omega0^2); for straight-line relative
    motion this equals the closest-approach distance.
    """
    rho0 = norm3(rho)
    omega0 = norm3(los_rate(rho, rho_dot))
    rdot0 = range_rate(rho, rho_dot)
    return rho0**2 * omega0 / jnp.sqrt(rdot0**2 + rho0**2 * omega0**2)


def zero_effort_miss(rho: Vector3, rho_dot: Vector3) -> Vector3:
    """Closest-approach vector of straight-line motion (from the impactor to the aim point), m.

    The component of ``rho`` perpendicular to ``rho_dot``; its norm is :func:`unforced_miss`.
    Accelerating the impactor along it reduces the miss.
    """
    return rho - (dot3(rho, rho_dot) / dot3(rho_dot, rho_dot)) * rho_dot


def time_to_go(rho: Vector3, rho_dot: Vector3) -> Scalar:
    """Time to go to closest approach of straight-line motion, s (seed 000 eq. 9 form)."""
    return -dot3(rho, rho_dot) / dot3(rho_dot, rho_dot)
