"""The target's silhouette in the B-plane: which impact points hit the body.

A run *hits* when the straight line through its B-plane point along the incoming asymptote S
meets the target. For a triaxial ellipsoid {x : x^T A x <= 1}, A = C diag(a^-2) C^T (C: body
axes in inertial, a: semi-axes), the shadow cast along S onto the B-plane is the ellipse

    y^T M^-1 y <= 1,   M = P A^-1 P^T,   P = [T; R] (the B-plane axes as rows),

(the projection of the ellipsoid x = A^-1/2 u, |u| <= 1, is P A^-1/2 u: an ellipse of shape
P A^-1 P^T). The target's gravity bends the approach towards it: a point mass of GM mu seen
at speed v_inf from infinity captures every asymptote within b = R sqrt(1 + 2 mu / (R v_inf^2))
of its centre (a sphere of radius R; Opik's gravitational focusing), applied to the silhouette
with the equal-volume radius R. At the papers' 10 km/s and a km-sized comet the factor is
1 + 1e-5: the silhouette is the rule.
"""

import jax.numpy as jnp

from .._types import Array, Float, Matrix3, Scalar


def silhouette_matrix(semi_axes_m, c_body, c_bi: Matrix3) -> Float[Array, "2 2"]:
    """M = P A^-1 P^T (m^2): the target's shadow along S in B-plane (T, R) coordinates.

    Args:
        semi_axes_m: ellipsoid semi-axes (m); c_body: body axes as columns, inertial;
        c_bi: B-plane frame rows (S, T, R), inertial.
    """
    a_inv = (c_body * jnp.asarray(semi_axes_m) ** 2) @ c_body.T  # C diag(a^2) C^T
    p = c_bi[1:]
    return p @ a_inv @ p.T


def focusing_factor(mu_m3s2, radius_m, speed_mps) -> Scalar:
    """Gravitational focusing of the capture cross-section's radius: sqrt(1 + 2 mu / (R v^2))."""
    return jnp.sqrt(1.0 + 2.0 * mu_m3s2 / (radius_m * speed_mps**2))


def silhouette_ratio(b_tr_m, m_silhouette, focusing) -> Scalar:
    """sqrt(y^T M^-1 y) / focusing of a B-plane point y = (B_T, B_R) (m): < 1 is a hit, and
    the value is the point's distance from the centre in units of the capture boundary along
    the same direction."""
    y = jnp.asarray(b_tr_m)
    m = jnp.asarray(m_silhouette)
    # M^-1 y written out (adj(M) y / det M): a solver's LAPACK call on the CPU wakes the BLAS
    # library's thread pool, whose threads then spin beside the batch (measured about a tenth
    # of an impactor study's CPU time).
    det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    x0 = (m[1, 1] * y[0] - m[0, 1] * y[1]) / det
    x1 = (m[0, 0] * y[1] - m[1, 0] * y[0]) / det
    return jnp.sqrt(y[0] * x0 + y[1] * x1) / focusing


__all__ = ["silhouette_matrix", "focusing_factor", "silhouette_ratio"]
