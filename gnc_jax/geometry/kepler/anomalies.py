"""Kepler's equation, elliptic and hyperbolic (Vallado algorithms 2 and 4), and the
conversions between true, eccentric, hyperbolic and mean anomalies."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .newton import _bracketed_newton

KEPLER_ITERATIONS = 12
"""Bracketed Newton steps for the elliptic and hyperbolic Kepler equations. From the starting
values below at most 7 reach machine precision for 0 <= e <= 0.999999 and 3 reach the
equation's conditioning for 1.000001 <= e <= 100 (tests/geometry/test_kepler.py)."""


def _elliptic_kepler_residual(ecc_anomaly: Array, params: tuple[Array, Array]):
    """Kepler's equation E - e sin E - M and its E-derivative; params = (e, M)."""
    e, mean_anomaly = params
    return ecc_anomaly - e * jnp.sin(ecc_anomaly) - mean_anomaly, 1.0 - e * jnp.cos(ecc_anomaly)


def _hyperbolic_kepler_residual(hyp_anomaly: Array, params: tuple[Array, Array]):
    """Hyperbolic Kepler equation e sinh H - H - M and its H-derivative; params = (e, M)."""
    e, mean_anomaly = params
    return (
        e * jnp.sinh(hyp_anomaly) - hyp_anomaly - mean_anomaly,
        e * jnp.cosh(hyp_anomaly) - 1.0,
    )


def _wrap_pi(angle: Array) -> Array:
    """Angle reduced to [-π, π)."""
    return angle - 2.0 * jnp.pi * jnp.floor((angle + jnp.pi) / (2.0 * jnp.pi))


def solve_kepler_elliptic(
    mean_anomaly: Float[ArrayLike, "..."],
    eccentricity: Float[ArrayLike, "..."],
    n_iter: int = KEPLER_ITERATIONS,
) -> Float[Array, "..."]:
    """Eccentric anomaly E of Kepler's equation M = E - e sin E, for 0 <= e < 1.

    The mean anomaly is reduced to [-π, π), where the root lies in [M - e, M + e], and solved
    from Danby's start E0 = M + 0.85 e sign(sin M); the returned E is shifted back by the same
    multiple of 2π, so E - e sin E = M holds for the unreduced M. Radians.
    """
    mean_anomaly = jnp.asarray(mean_anomaly, dtype=float)
    e = jnp.asarray(eccentricity, dtype=float)
    m_reduced = _wrap_pi(mean_anomaly)
    m_shift = mean_anomaly - m_reduced

    e0 = m_reduced + 0.85 * e * jnp.sign(jnp.sin(m_reduced))
    ecc_anomaly = _bracketed_newton(
        _elliptic_kepler_residual, (e, m_reduced), e0, m_reduced - e, m_reduced + e, n_iter
    )
    return ecc_anomaly + m_shift


def solve_kepler_hyperbolic(
    mean_anomaly: Float[ArrayLike, "..."],
    eccentricity: Float[ArrayLike, "..."],
    n_iter: int = KEPLER_ITERATIONS,
) -> Float[Array, "..."]:
    """Hyperbolic anomaly H of the hyperbolic Kepler equation M = e sinh H - H, for e > 1.

    Since sinh H >= H for H >= 0 (and the equation is odd), the root lies between
    asinh(M/e) and asinh(M/(e - 1)). Two starting values bracket it: one fixed-point pass of
    H = asinh((M + H)/e) from the first bound (good for large |M|), and the root of the cubic
    (e - 1) H + e H³/6 = M from sinh H ≈ H + H³/6 (good near periapsis and for e -> 1);
    Newton starts from the one with the shorter Newton step. Radians.
    """
    mean_anomaly = jnp.asarray(mean_anomaly, dtype=float)
    e = jnp.asarray(eccentricity, dtype=float)

    params = (e, mean_anomaly)
    near = jnp.arcsinh(mean_anomaly / e)
    far = jnp.arcsinh(mean_anomaly / (e - 1.0))
    fixed_point_start = jnp.arcsinh((mean_anomaly + near) / e)
    # Cardano's root of H³ + 3 c H - 2 b = 0, c = 2 (e - 1) / e, b = 3 M / e, in the form
    # u - c / u that cancels least (u = cbrt(b + sqrt(b² + c³)) has the sign of M).
    b = 3.0 * mean_anomaly / e
    c = 2.0 * (e - 1.0) / e
    u = jnp.cbrt(b + jnp.sign(b) * jnp.sqrt(b * b + c**3))
    cubic_start = jnp.where(u == 0.0, 0.0, u - c / jnp.where(u == 0.0, 1.0, u))
    cubic_start = jnp.where(jnp.abs(cubic_start) < jnp.abs(far), cubic_start, far)
    f_fixed, df_fixed = _hyperbolic_kepler_residual(fixed_point_start, params)
    f_cubic, df_cubic = _hyperbolic_kepler_residual(cubic_start, params)
    h0 = jnp.where(
        jnp.abs(f_cubic / df_cubic) < jnp.abs(f_fixed / df_fixed), cubic_start, fixed_point_start
    )
    lower, upper = jnp.minimum(near, far), jnp.maximum(near, far)
    return _bracketed_newton(_hyperbolic_kepler_residual, params, h0, lower, upper, n_iter)


def true_anomaly_from_eccentric(
    eccentric_anomaly: Float[ArrayLike, "..."], eccentricity: Float[ArrayLike, "..."]
) -> Float[Array, "..."]:
    """True anomaly ν from eccentric anomaly E (e < 1): tan(ν/2) = sqrt((1+e)/(1-e)) tan(E/2).

    Evaluated as 2 atan2(sqrt(1+e) sin(E/2), sqrt(1-e) cos(E/2)), which keeps the revolution
    count of E (ν and E lie in the same 2π interval). Radians.
    """
    half = 0.5 * jnp.asarray(eccentric_anomaly, dtype=float)
    e = jnp.asarray(eccentricity, dtype=float)
    return 2.0 * jnp.arctan2(jnp.sqrt(1.0 + e) * jnp.sin(half), jnp.sqrt(1.0 - e) * jnp.cos(half))


def eccentric_anomaly_from_true(
    true_anomaly: Float[ArrayLike, "..."], eccentricity: Float[ArrayLike, "..."]
) -> Float[Array, "..."]:
    """Eccentric anomaly E from true anomaly ν (e < 1), inverse of `true_anomaly_from_eccentric`."""
    half = 0.5 * jnp.asarray(true_anomaly, dtype=float)
    e = jnp.asarray(eccentricity, dtype=float)
    return 2.0 * jnp.arctan2(jnp.sqrt(1.0 - e) * jnp.sin(half), jnp.sqrt(1.0 + e) * jnp.cos(half))


def true_anomaly_from_hyperbolic(
    hyperbolic_anomaly: Float[ArrayLike, "..."], eccentricity: Float[ArrayLike, "..."]
) -> Float[Array, "..."]:
    """True anomaly ν from hyperbolic anomaly H (e > 1): tan(ν/2) = sqrt((e+1)/(e-1)) tanh(H/2)."""
    e = jnp.asarray(eccentricity, dtype=float)
    tanh_half = jnp.tanh(0.5 * jnp.asarray(hyperbolic_anomaly, dtype=float))
    return 2.0 * jnp.arctan(jnp.sqrt((e + 1.0) / (e - 1.0)) * tanh_half)


def hyperbolic_anomaly_from_true(
    true_anomaly: Float[ArrayLike, "..."], eccentricity: Float[ArrayLike, "..."]
) -> Float[Array, "..."]:
    """Hyperbolic anomaly H from true anomaly ν (e > 1, |ν| < acos(-1/e))."""
    e = jnp.asarray(eccentricity, dtype=float)
    tan_half = jnp.tan(0.5 * jnp.asarray(true_anomaly, dtype=float))
    return 2.0 * jnp.arctanh(jnp.sqrt((e - 1.0) / (e + 1.0)) * tan_half)


def mean_anomaly_from_true(
    true_anomaly: Float[ArrayLike, "..."], eccentricity: Float[ArrayLike, "..."]
) -> Float[Array, "..."]:
    """Mean anomaly from true anomaly: M = E - e sin E (e < 1) or M = e sinh H - H (e > 1)."""
    e = jnp.asarray(eccentricity, dtype=float)
    hyperbolic = e > 1.0
    e_ell = jnp.where(hyperbolic, 0.5, e)
    e_hyp = jnp.where(hyperbolic, e, 2.0)
    nu_hyp = jnp.where(hyperbolic, true_anomaly, 0.0)
    ecc_anomaly = eccentric_anomaly_from_true(true_anomaly, e_ell)
    hyp_anomaly = hyperbolic_anomaly_from_true(nu_hyp, e_hyp)
    return jnp.where(
        hyperbolic,
        e_hyp * jnp.sinh(hyp_anomaly) - hyp_anomaly,
        ecc_anomaly - e_ell * jnp.sin(ecc_anomaly),
    )


def true_anomaly_from_mean(
    mean_anomaly: Float[ArrayLike, "..."],
    eccentricity: Float[ArrayLike, "..."],
    n_iter: int = KEPLER_ITERATIONS,
) -> Float[Array, "..."]:
    """True anomaly from mean anomaly by Kepler's equation, elliptic (e < 1) or hyperbolic (e > 1).

    For e < 1 the result keeps the revolution count of M; for e > 1 it lies in
    (-acos(-1/e), acos(-1/e)). Radians.
    """
    e = jnp.asarray(eccentricity, dtype=float)
    hyperbolic = e > 1.0
    e_ell = jnp.where(hyperbolic, 0.5, e)
    e_hyp = jnp.where(hyperbolic, e, 2.0)
    m_ell = jnp.where(hyperbolic, 0.0, mean_anomaly)
    m_hyp = jnp.where(hyperbolic, mean_anomaly, 0.0)
    nu_ell = true_anomaly_from_eccentric(solve_kepler_elliptic(m_ell, e_ell, n_iter), e_ell)
    nu_hyp = true_anomaly_from_hyperbolic(solve_kepler_hyperbolic(m_hyp, e_hyp, n_iter), e_hyp)
    return jnp.where(hyperbolic, nu_hyp, nu_ell)
