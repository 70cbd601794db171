"""B-plane frame and B-plane coordinates (seed 000 §1.1, eqs. 1-2).

S is along the incoming asymptote (for a small body: the relative velocity), T lies in the
reference plane (normal ``h``: the target's orbit plane, the ecliptic when none is given) and
R = S x T completes the right-handed triad. ``C_BI = [S T R]^T`` maps inertial vectors to the
B-plane frame.
"""

import jax.numpy as jnp
import numpy as np

from .._types import Array, Float, Matrix3, Vector3

#: |S x h| below this is treated as S parallel to h, where T is undefined.
PARALLEL_TOLERANCE = 1e-9


class BPlaneError(ValueError):
    """The B-plane frame is undefined (S parallel to the reference-plane normal)."""


def b_plane_frame(v_inf: Vector3, ref_normal: Vector3) -> Matrix3:
    """Rotation ``C_BI = [S T R]^T`` from inertial to the B-plane frame (seed 000 eqs. 1-2).

    Args:
        v_inf: incoming asymptote velocity (any units; only the direction is used).
        ref_normal: normal of the reference plane (any length).

    Returns:
        3x3 matrix whose rows are S, T, R. When S is parallel to ``ref_normal`` the rows are NaN;
        use :func:`check_b_plane_frame` on concrete inputs to get a clear error instead.
    """
    s = v_inf / jnp.linalg.norm(v_inf)
    sxh = jnp.cross(s, ref_normal)
    n = jnp.linalg.norm(sxh)
    t = jnp.where(n > PARALLEL_TOLERANCE * jnp.linalg.norm(ref_normal), sxh / n, jnp.nan)
    r = jnp.cross(s, t)
    return jnp.stack([s, t, r])


def check_b_plane_frame(v_inf, ref_normal) -> None:
    """Raise :class:`BPlaneError` when S is parallel to the reference normal (concrete inputs)."""
    v = np.asarray(v_inf, dtype=float)
    h = np.asarray(ref_normal, dtype=float)
    if not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0.0:
        raise BPlaneError("B-plane: the approach velocity must be a finite non-zero vector")
    if np.linalg.norm(h) == 0.0:
        raise BPlaneError("B-plane: the reference-plane normal must be non-zero")
    s = v / np.linalg.norm(v)
    if np.linalg.norm(np.cross(s, h)) <= PARALLEL_TOLERANCE * np.linalg.norm(h):
        raise BPlaneError(
            "B-plane: the approach direction S is parallel to the reference-plane normal h, "
            "so the T axis (S x h) is undefined; choose another reference plane"
        )


def b_plane_crossing(
    r: Vector3, v: Vector3, c_bi: Matrix3
) -> tuple[Float[Array, "2"], Float[Array, ""]]:
    """Straight-line B-plane crossing of a relative trajectory.

    The plane passes through the target (origin) normal to S. A straight line ``r + v t``
    crosses it at ``t_tof = -(r.S)/(v.S)`` (the linearised time of flight, s).

    Args:
        r: position relative to the target (m), inertial.
        v: velocity relative to the target (m/s), inertial.
        c_bi: B-plane frame from :func:`b_plane_frame`.

    Returns:
        ``(B, t_tof)``: B = (B_T, B_R) in m, and the time of flight to the plane in s.
    """
    s = c_bi[0]
    t_tof = -jnp.dot(r, s) / jnp.dot(v, s)
    b = r + v * t_tof
    return c_bi[1:] @ b, t_tof


def b_plane_point_to_inertial(b_tr: Float[Array, "2"], c_bi: Matrix3) -> Vector3:
    """Inertial position of the B-plane point (B_T, B_R) (m)."""
    return jnp.stack([b_tr[0] * c_bi[1, i] + b_tr[1] * c_bi[2, i] for i in range(3)])
