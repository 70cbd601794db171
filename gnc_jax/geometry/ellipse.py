"""B-plane error ellipse of the predicted impact point (seed 000 §2, eqs. 8-13 and 18)."""

import jax.numpy as jnp

from .._types import Array, Covariance6, Float, Matrix3, Scalar


def straight_line_stm(t_go) -> Float[Array, "6 6"]:
    """State-transition matrix of straight-line relative motion, [[I, t_go I], [0, I]]."""
    eye = jnp.eye(3)
    zero = jnp.zeros((3, 3))
    return jnp.block([[eye, t_go * eye], [zero, eye]])


def map_covariance(p0: Covariance6, t_go) -> Covariance6:
    """P_f = Phi(t_f, t0) P0 Phi^T (seed 000 eq. 8) with the straight-line Phi (eq. 9)."""
    phi = straight_line_stm(t_go)
    return phi @ p0 @ phi.T


def b_plane_position_covariance(p0: Covariance6, t_go, c_bi: Matrix3) -> Float[Array, "2 2"]:
    """D: the (T, R) position block of P_f in the B-plane frame (seed 000 eq. 10), m^2.

    Computed without forming the 6x6 product: position block of Phi P Phi^T is
    P_rr + t_go (P_rv + P_vr) + t_go^2 P_vv. ``p0`` is read entry by entry (``p0[i, j]``), so
    it may be a dense 6x6 array or the packed covariance a filter carries
    (``navigation.packed_ekf.PackedCovariance``): under ``vmap`` the packed entries are read
    where they are, with no 6x6 matrix assembled from them (its stacking costs a copy per
    entry on a GPU). The products are :func:`~gnc_jax._numerics.matmul`'s, term for term.
    """
    t2 = t_go**2
    prr = [
        [p0[i, j] + t_go * (p0[i, j + 3] + p0[i + 3, j]) + t2 * p0[i + 3, j + 3] for j in range(3)]
        for i in range(3)
    ]
    tr = c_bi[1:]
    a = [[_row_times(tr, k, [prr[l][j] for l in range(3)]) for j in range(3)] for k in range(2)]
    return jnp.stack(
        [
            jnp.stack([_row_times(a, k, [tr[m, l] for l in range(3)], True) for m in range(2)])
            for k in range(2)
        ]
    )


def _row_times(a, k, column, nested=False):
    """Row ``k`` of ``a`` times ``column``, summed as :func:`~gnc_jax._numerics.matmul` does."""
    row = a[k] if nested else [a[k, l] for l in range(len(column))]
    return sum(row[l] * column[l] for l in range(1, len(column))) + row[0] * column[0]


def error_ellipse(d: Float[Array, "2 2"]) -> tuple[Scalar, Scalar, Scalar]:
    """Semi-axes E >= F and orientation phi_F of the error ellipse (seed 000 eqs. 12-13).

    Args:
        d: 2x2 covariance [[sT^2, mu sT sR], [mu sT sR, sR^2]] (m^2).

    Returns:
        ``(E, F, phi_F)``: E, F in m; phi_F (rad) is the angle from the T axis of the minor-axis
        direction (eigenvector of lambda_2), in (-pi/2, pi/2].
    """
    st2, sr2, c = d[0, 0], d[1, 1], d[0, 1]
    half_sum = 0.5 * (st2 + sr2)
    half_root = 0.5 * jnp.sqrt((st2 - sr2) ** 2 + 4.0 * c**2)
    lam1 = half_sum + half_root
    lam2 = jnp.maximum(half_sum - half_root, 0.0)
    # Major axis at 0.5 atan2(2c, sT^2 - sR^2) (eq. 13); the minor axis is 90 deg from it.
    phi_e = 0.5 * jnp.arctan2(2.0 * c, st2 - sr2)
    phi_f = phi_e + jnp.pi / 2
    phi_f = jnp.where(phi_f > jnp.pi / 2, phi_f - jnp.pi, phi_f)
    return jnp.sqrt(lam1), jnp.sqrt(lam2), phi_f


def mean_position_error(d: Float[Array, "2 2"]) -> Scalar:
    """sigma_B = sqrt(sT^2 + sR^2) = sqrt(E^2 + F^2) (seed 000 eq. 11), m."""
    return jnp.sqrt(d[0, 0] + d[1, 1])


def ellipse_probability(k):
    """Probability that a 2-D Gaussian point lies inside the k-sigma ellipse (seed 000 eq. 18).

    P = 1 - exp(-k^2/2). (The paper's Table 1 misprints k = 3.0 and 3.5.)
    """
    return 1.0 - jnp.exp(-0.5 * jnp.asarray(k) ** 2)
