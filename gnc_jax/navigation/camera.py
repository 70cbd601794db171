"""Pinhole navigation camera (seed 002 §3.1, measurement model (p, l)).

A camera frame has its boresight z_c along the line of sight it points at; the target's image
coordinates on the focal plane are p = f x_c / z_c and l = f y_c / z_c (m). The filter works with
p/f and l/f (rad, tangent-plane angles) so that its numbers are well scaled.
"""

import math

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


# Taylor coefficients of sin(a)/a and (1 - cos(a))/a^2 in a^2 (16 terms each): the series of
# small_rotation_entries, exact to rounding (2e-15) for rotation angles up to pi.
_SINC = tuple((-1) ** n / math.factorial(2 * n + 1) for n in range(16))
_COSC = tuple((-1) ** n / math.factorial(2 * n + 2) for n in range(16))
SERIES_ANGLE_MAX = math.pi
"""Largest rotation angle (rad) for which :func:`small_rotation_entries` is exact to rounding."""


def _horner(coefficients, x):
    acc = coefficients[-1]
    for c in reversed(coefficients[:-1]):
        acc = acc * x + c
    return acc


def rotation_series(theta: Vector3) -> tuple:
    """``(sin(a)/a, (1 - cos a)/a^2)`` of the rotation vector ``theta`` (a = |theta|),
    from the 16-term series in a^2 of :func:`small_rotation_entries`."""
    a2 = theta[0] * theta[0] + theta[1] * theta[1] + theta[2] * theta[2]
    return _horner(_SINC, a2), _horner(_COSC, a2)


def small_rotation_entries(theta: Vector3, series=rotation_series) -> tuple:
    """The entries (row by row, a 3-tuple of 3-tuples of scalars) of :func:`small_rotation`,
    from power series in |theta|^2: R = cos(a) I + (sin(a)/a) [theta x] + ((1 - cos a)/a^2)
    theta theta^T, with sin(a)/a and (1 - cos a)/a^2 as 16-term series in a^2 = theta . theta.

    No square root, division or trigonometric function: under ``vmap`` it is a few dozen
    multiply-adds per run instead of a sqrt, a sin and a cos (measured 12 % of the impactor's
    closed loop, which rotates twice per image). Exact to rounding (within 2e-15 of Rodrigues'
    formula, tested against scipy) for angles up to ``SERIES_ANGLE_MAX`` = pi; use it for
    attitude errors (the impactor's, at most 0.1 rad 1-sigma per axis, stay far below), and
    :func:`small_rotation` for arbitrary rotations.

    ``series``: how the three series values are computed (:func:`rotation_series`; a batched
    caller computes them once into memory with :func:`~gnc_jax._numerics.computed_once`: left
    to fusion, each of the nine entries recomputes both series).
    """
    t = (theta[0], theta[1], theta[2])
    s, c = series(theta)  # sin(a)/a, (1 - cos a)/a^2
    d = 1.0 - c * (t[0] * t[0] + t[1] * t[1] + t[2] * t[2])  # cos(a)
    st = (s * t[0], s * t[1], s * t[2])
    return (
        (d + c * t[0] * t[0], c * t[0] * t[1] - st[2], c * t[0] * t[2] + st[1]),
        (c * t[1] * t[0] + st[2], d + c * t[1] * t[1], c * t[1] * t[2] - st[0]),
        (c * t[2] * t[0] - st[1], c * t[2] * t[1] + st[0], d + c * t[2] * t[2]),
    )


def rotate_rows(entries: tuple, rows: tuple) -> tuple:
    """The rows of R C for R given by its ``entries`` (row by row) and C by its ``rows``:
    row i is sum_k R[i][k] C[k], in the order of :func:`~gnc_jax._numerics.matmul`."""
    return tuple(
        entries[i][1] * rows[1] + entries[i][2] * rows[2] + entries[i][0] * rows[0]
        for i in range(3)
    )


def project(c_ci: Matrix3, los: Vector3, focal_length_m) -> Float[Array, "2"]:
    """Focal-plane coordinates (p, l) in m of a target seen along ``los`` (inertial)."""
    xc = matvec3(c_ci, los)
    return focal_length_m * xc[:2] / xc[2]


def los_angles(c_ci: Matrix3, los: Vector3) -> Float[Array, "2"]:
    """Tangent-plane angles (p/f, l/f) in rad of a target seen along ``los``."""
    xc = matvec3(c_ci, los)
    return xc[:2] / xc[2]
