"""B-plane error ellipse of the predicted impact point (seed 000 §2, eqs. 8-13 and 18)."""

import jax.numpy as jnp

from .._numerics import matmul
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
    P_rr + t_go (P_rv + P_vr) + t_go^2 P_vv.
    """
    prr = p0[:3, :3] + t_go * (p0[:3, 3:] + p0[3:, :3]) + t_go**2 * p0[3:, 3:]
    tr = c_bi[1:]
    return matmul(matmul(tr, prr), tr.T)


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
