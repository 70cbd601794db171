"""The EKF of ``navigation.ekf`` for LOS angles, in packed form (the intercept's 1 s loop).

Same filter, same model: state x = (r, v) relative to the target, straight-line prediction
(Phi = [[I, dt I], [0, I]] plus white acceleration), tangent-plane angle measurements with white
noise of equal variance on both axes. Three facts of this model make it cheap per run:

* the covariance is symmetric: it is carried as its 21 unique entries (upper triangle, row by
  row), each its own array, so that under ``vmap`` every entry is one contiguous batch vector
  (no (batch, 6, 6) slicing and re-stacking);
* an angle depends on the position only, H = [h_r, 0]: P H^T needs the first three columns of
  P, and S = h_r P_rr h_r^T + R;
* the two angles have independent noise (R = sigma^2 I), so the update is two scalar updates
  in sequence (exactly the joint update, Bierman 1977 §3.2): K = P h^T / s and
  P <- P - (P h^T)(P h^T)^T / s, no matrix inverse. The second scalar keeps the first's
  linearisation point: its innovation is corrected by h_2 (x_1 - x_0).

``navigation.ekf.ekf_update`` (dense, any measurement) is the reference the tests hold this to.
"""

from typing import NamedTuple

import jax.numpy as jnp

from .._types import Array, Covariance6, Float, Scalar, Vector3
from .ekf import _S_FLOOR, _symmetric

N_STATE = 6
_INDEX = {}
for _i in range(N_STATE):
    for _j in range(_i, N_STATE):
        _INDEX[(_i, _j)] = len(_INDEX)


def packed_index(i: int, j: int) -> int:
    """Position of entry (i, j) of a symmetric 6x6 matrix in its packed tuple."""
    return _INDEX[(min(i, j), max(i, j))]


class PackedCovariance(NamedTuple):
    """The 21 unique entries of a 6x6 covariance: ``entries[packed_index(i, j)]`` = P[i, j]."""

    entries: tuple

    def __getitem__(self, ij) -> Scalar:  # P[i, j] for a pair of Python ints
        if isinstance(ij, tuple):
            return self.entries[packed_index(*ij)]
        return tuple.__getitem__(self, ij)


def pack(p: Covariance6) -> PackedCovariance:
    """The packed form of a symmetric 6x6 matrix (its upper triangle)."""
    return PackedCovariance(tuple(p[i, j] for (i, j) in _INDEX))


def unpack(pk: PackedCovariance) -> Covariance6:
    """The symmetric 6x6 matrix of a packed covariance."""
    return _symmetric(lambda i, j: pk[i, j], N_STATE)


def propagate_packed(pk: PackedCovariance, dt, q_accel) -> PackedCovariance:
    """P <- Phi P Phi^T + Q for straight-line motion over ``dt`` (``ekf.propagate_covariance``
    with no accelerometer term), on the packed entries.

    With Phi = [[I, dt I], [0, I]]: P_rr += dt (P_rv + P_vr) + dt^2 P_vv, P_rv += dt P_vv;
    Q of white acceleration q: dt^3/3 q, dt^2/2 q, dt q on the rr, rv, vv diagonals.
    """
    q_rr, q_rv, q_vv = q_accel * dt**3 / 3.0, q_accel * dt**2 / 2.0, q_accel * dt
    out = []
    for i, j in _INDEX:
        if j < 3:  # both position
            v = pk[i, j] + dt * (pk[i, j + 3] + pk[i + 3, j]) + dt * dt * pk[i + 3, j + 3]
            v = v + q_rr if i == j else v
        elif i < 3:  # position-velocity
            v = pk[i, j] + dt * pk[i + 3, j]
            v = v + q_rv if j == i + 3 else v
        else:
            v = pk[i, j] + q_vv if i == j else pk[i, j]
        out.append(v)
    return PackedCovariance(tuple(out))


class LOSGain(NamedTuple):
    """The corrections of one LOS update before they are applied to the covariance.

    ``r``, ``v``: the updated mean; ``terms``: one (w, u) pair of 6-tuples per scalar update,
    P <- P - sum w u^T (w = u / s); see :func:`los_gain`.
    """

    r: Vector3
    v: Vector3
    terms: tuple


def los_gain(
    r: Vector3,
    v: Vector3,
    pk: PackedCovariance,
    h_r: Float[Array, "m 3"],
    innovation: Float[Array, " m"],
    r_var: Scalar,
    angles: int = 2,
    valid=True,
) -> LOSGain:
    """Sequential scalar EKF updates with Jacobian rows H_a = [h_r[a], 0] (at the prior),
    independent noise of variance ``r_var`` each, for the first ``angles`` (static) rows.

    Update a: u = P_a H_a^T, s = H_a u + R, x <- x + u (nu_a / s), P_{a+1} = P_a - u u^T / s;
    nu_a is the innovation z_a - h_a(x_0) less H_a (x_a - x_0), so that all rows keep the prior
    linearisation point (the joint update). Only the first three columns of P are read: the
    second row's u is P_0 H_2^T - w_1 (u_1 . H_2), and the covariance update is deferred to
    :func:`apply_gain` (an elementwise pass over the 21 entries). When ``valid`` is false (a
    rejected image) the gain is zero: the prior is kept.
    """
    terms, dr, dv = [], jnp.zeros(3), jnp.zeros(3)
    for a in range(angles):
        h = h_r[a]
        u = [sum(pk[i, k] * h[k] for k in range(1, 3)) + pk[i, 0] * h[0] for i in range(6)]
        for w_prev, u_prev in terms:  # the rows already applied: P_a = P_0 - sum w u^T
            c = u_prev[0] * h[0] + u_prev[1] * h[1] + u_prev[2] * h[2]
            u = [ui - wi * c for ui, wi in zip(u, w_prev)]
        # the floor of ekf_update: a certain filter (P = 0) of a noiseless measurement gains 0
        s = h[0] * u[0] + h[1] * u[1] + h[2] * u[2] + r_var + _S_FLOOR
        inv_s = 1.0 / s
        nu = innovation[a] - (h[0] * dr[0] + h[1] * dr[1] + h[2] * dr[2])
        gain = nu * inv_s
        dr = dr + jnp.stack([u[0] * gain, u[1] * gain, u[2] * gain])
        dv = dv + jnp.stack([u[3] * gain, u[4] * gain, u[5] * gain])
        terms.append((tuple(ui * inv_s for ui in u), tuple(u)))
    if valid is not True:
        keep = lambda a: jnp.where(valid, a, jnp.zeros_like(a))  # noqa: E731
        dr, dv = keep(dr), keep(dv)
        terms = [(tuple(keep(wi) for wi in w), u) for w, u in terms]
    return LOSGain(r + dr, v + dv, tuple(terms))


def apply_gain(pk: PackedCovariance, terms: tuple) -> PackedCovariance:
    """P - sum w u^T over the (w, u) terms of :func:`los_gain`, entry by entry."""
    out = []
    for i, j in _INDEX:
        p_ij = pk[i, j]
        for w, u in terms:
            p_ij = p_ij - w[i] * u[j]
        out.append(p_ij)
    return PackedCovariance(tuple(out))


def los_update(
    r: Vector3,
    v: Vector3,
    pk: PackedCovariance,
    h_r: Float[Array, "2 3"],
    innovation: Float[Array, "2"],
    r_var: Scalar,
    valid=True,
    angles: int = 2,
) -> tuple[Vector3, Vector3, PackedCovariance]:
    """EKF update with the two tangent-plane angles (Jacobian rows ``h_r`` at the prior,
    innovations z - h(x_hat), variance ``r_var`` each): :func:`los_gain` then
    :func:`apply_gain`.

    ``angles = 1`` (static) takes the first angle only: when the second's innovation, its
    Jacobian's projection on the first's and their cross covariance are zero (a planar
    intercept, whose out-of-plane angle is exact), the second update changes only the
    out-of-plane entries, which nothing reads. When ``valid`` is false the prior is returned.
    """
    gain = los_gain(r, v, pk, h_r, innovation, r_var, angles, valid)
    return gain.r, gain.v, apply_gain(pk, gain.terms)


__all__ = [
    "PackedCovariance",
    "los_update",
    "pack",
    "packed_index",
    "propagate_packed",
    "LOSGain",
    "apply_gain",
    "los_gain",
    "unpack",
]
