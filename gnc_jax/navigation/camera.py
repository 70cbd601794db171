"""Pinhole navigation camera (seed 002 §3.1, measurement model (p, l); SPEC §5).

A camera frame has its boresight z_c along the line of sight it points at; the target's image
coordinates on the focal plane are p = f x_c / z_c and l = f y_c / z_c (m). The filter works with
p/f and l/f (rad, tangent-plane angles) so that its numbers are well scaled.
"""

import jax.numpy as jnp

from .._types import Array, Float, Matrix3, Vector3


def camera_attitude(boresight: Vector3, up_hint: Vector3) -> Matrix3:
    """Rotation C_cI (rows x_c, y_c, z_c) pointing the boresight z_c along ``boresight``.

    ``up_hint`` fixes the roll: x_c is along up_hint x z_c (the B-plane R axis is used).
    """
    z = boresight / jnp.linalg.norm(boresight)
    x = jnp.cross(up_hint, z)
    x = x / jnp.linalg.norm(x)
    y = jnp.cross(z, x)
    return jnp.stack([x, y, z])


def small_rotation(theta: Vector3) -> Matrix3:
    """Rotation matrix of the rotation vector ``theta`` (rad), Rodrigues' formula."""
    angle = jnp.sqrt(jnp.dot(theta, theta) + 1e-300)
    k = theta / angle
    kx = jnp.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return jnp.eye(3) + jnp.sin(angle) * kx + (1.0 - jnp.cos(angle)) * kx @ kx


def project(c_ci: Matrix3, los: Vector3, focal_length_m) -> Float[Array, "2"]:
    """Focal-plane coordinates (p, l) in m of a target seen along ``los`` (inertial)."""
    xc = c_ci @ los
    return focal_length_m * xc[:2] / xc[2]


def los_angles(c_ci: Matrix3, los: Vector3) -> Float[Array, "2"]:
    """Tangent-plane angles (p/f, l/f) in rad of a target seen along ``los``."""
    xc = c_ci @ los
    return xc[:2] / xc[2]
