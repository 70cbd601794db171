"""Pinhole navigation camera (seed 002 §3.1, measurement model (p, l)).

A camera frame has its boresight z_c along the line of sight it points at; the target's image
coordinates on the focal plane are p = f x_c / z_c and l = f y_c / z_c (m). The filter works with
p/f and l/f (rad, tangent-plane angles) so that its numbers are well scaled.
"""

import jax.numpy as jnp

from .._numerics import cross3, dot3, matvec3
from .._types import Array, Float, Matrix3, Vector3


def camera_attitude(boresight: Vector3, up_hint: Vector3) -> Matrix3:
    """Rotation C_cI (rows x_c, y_c, z_c) pointing the boresight z_c along ``boresight``.

    ``up_hint`` fixes the roll: x_c is along up_hint x z_c (the B-plane R axis is used).
    """
    return jnp.stack(camera_axes(boresight, up_hint))


def camera_axes(boresight: Vector3, up_hint: Vector3) -> tuple[Vector3, Vector3, Vector3]:
    """The rows (x_c, y_c, z_c) of :func:`camera_attitude`, unstacked: a caller that takes
    products with each row keeps them in registers under ``vmap`` (the stacked (batch, 3, 3)
    matrix is stored and read back with a transposed layout on XLA CPU)."""
    z = boresight / jnp.sqrt(dot3(boresight, boresight))
    x = cross3(up_hint, z)
    x = x / jnp.sqrt(dot3(x, x))
    y = cross3(z, x)
    return x, y, z


def small_rotation(theta: Vector3) -> Matrix3:
    """Rotation matrix of the rotation vector ``theta`` (rad), Rodrigues' formula."""
    angle = jnp.sqrt(dot3(theta, theta) + 1e-300)
    k = theta / angle
    s, c1 = jnp.sin(angle), 1.0 - jnp.cos(angle)
    # I + sin(a) [k x] + (1 - cos(a)) [k x]^2, with [k x]^2 = k k^T - I written out.
    kk = k[:, None] * k[None, :]
    kx = jnp.stack(
        [
            jnp.stack([0.0 * k[0], -k[2], k[1]]),
            jnp.stack([k[2], 0.0 * k[0], -k[0]]),
            jnp.stack([-k[1], k[0], 0.0 * k[0]]),
        ]
    )
    return jnp.eye(3) * (1.0 - c1) + s * kx + c1 * kk


def project(c_ci: Matrix3, los: Vector3, focal_length_m) -> Float[Array, "2"]:
    """Focal-plane coordinates (p, l) in m of a target seen along ``los`` (inertial)."""
    xc = matvec3(c_ci, los)
    return focal_length_m * xc[:2] / xc[2]


def los_angles(c_ci: Matrix3, los: Vector3) -> Float[Array, "2"]:
    """Tangent-plane angles (p/f, l/f) in rad of a target seen along ``los``."""
    xc = matvec3(c_ci, los)
    return xc[:2] / xc[2]
