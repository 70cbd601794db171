# ruff: noqa: F722  (jaxtyping shape strings such as "" and "3 3" are not Python expressions)
"""Two-body (Keplerian) motion: Kepler's equation, classical elements and f-g propagation.

Everything here is a pure function of arrays for one orbit; `jax.vmap` adds batches. Iterative
solves run a fixed number of bracketed Newton steps in `lax.fori_loop` (no data-dependent trip
count, so a vmapped batch costs the same as one orbit times the batch size) and then take one
last Newton step outside the loop with the iterate held constant. That step leaves the value
unchanged at convergence but makes first derivatives exact by the implicit-function theorem,
dx/dθ = -(∂F/∂θ) / (∂F/∂x), instead of differentiating through the iteration history.

Units are whatever the caller uses consistently (SI in gnc_jax: m, m/s, s, m³/s²); angles are
radians. Hyperbolic orbits have a negative semi-major axis. Parabolic (e = 1) orbits are covered
by the universal-variable propagator but not by the element conversions, and rectilinear
(zero angular momentum) orbits by neither.

References:
    Vallado, D. A. (2013), Fundamentals of Astrodynamics and Applications, 4th ed.:
        algorithms 2 (KepEqtnE), 4 (KepEqtnH), 8 (KEPLER, universal variables),
        9 (RV2COE), 10 (COE2RV); eqs. 2-58 to 2-67 (f and g functions).
    Danby, J. M. A. (1988), Fundamentals of Celestial Mechanics, 2nd ed., §6.6
        (starting value of the elliptic Kepler solve).
    Seed 001 (Zhang, Wang, Huang 2009), eqs. 27-32: time of flight from Kepler's equation.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float

KEPLER_ITERATIONS = 12
"""Bracketed Newton steps for the elliptic and hyperbolic Kepler equations. From the starting
values below at most 7 reach machine precision for 0 <= e <= 0.999999 and 3 reach the
equation's conditioning for 1.000001 <= e <= 100 (tests/geometry/test_kepler.py)."""

UNIVERSAL_ITERATIONS = 30
"""Bracketed Newton steps for the universal anomaly. Over ±3000-day arcs random ellipses need
at most 8 and hyperbolas 10; near-parabolic orbits (|1 - e| < 1e-3) take a few bisection
steps first and need up to 20 (tests/geometry/test_kepler.py)."""

_STUMPFF_SERIES_LIMIT = 1.0  # |psi| below which the Stumpff functions use their series
_STUMPFF_SERIES_TERMS = 10  # (|psi| < 1: the last term is < 1 / 21! ~ 2e-20)


class OrbitalElements(NamedTuple):
    """Classical orbital elements of a conic in the frame of the state vectors.

    Conventions (Vallado algorithm 9): for an equatorial orbit (i = 0 or π) the node line is
    taken along +x, so `raan_rad` = 0 and `arg_periapsis_rad` is the longitude of periapsis;
    for a circular orbit the periapsis is put at the node, so `arg_periapsis_rad` = 0 and
    `true_anomaly_rad` is the argument of latitude. `raan_rad` and `arg_periapsis_rad` lie in
    [0, 2π), `true_anomaly_rad` in (-π, π].
    """

    semi_major_axis: Float[Array, "..."]
    """a, same length unit as the state; negative for hyperbolic orbits."""
    eccentricity: Float[Array, "..."]
    inclination_rad: Float[Array, "..."]
    raan_rad: Float[Array, "..."]
    """Right ascension (longitude) of the ascending node Ω."""
    arg_periapsis_rad: Float[Array, "..."]
    """Argument of periapsis ω."""
    true_anomaly_rad: Float[Array, "..."]


def _bracketed_newton(
    residual: Callable[[Array, tuple[Array, ...]], tuple[Array, Array]],
    params: tuple[Array, ...],
    x0: Array,
    lower: Array,
    upper: Array,
    n_iter: int,
) -> Array:
    """Root of an increasing function by Newton steps safeguarded with bisection.

    ``residual(x, params) -> (F, dF/dx)`` with F increasing in x and F(lower) <= 0 <= F(upper).
    The loop runs on gradient-stopped copies of everything, so automatic differentiation never
    enters it; the final Newton step with the live ``params`` carries the implicit-function
    derivative. A Newton
    step that leaves the bracket is replaced by bisection (as in Numerical Recipes' ``rtsafe``),
    so the iteration cannot diverge; except that the first step across an analytic bound not
    yet evaluated goes to that bound, because a root close to such a bound would otherwise be
    approached by bisection only.
    """
    frozen = lax.stop_gradient(params)

    def step(_, carry):
        x, lo, hi, lo_untried, hi_untried = carry
        f, df = residual(x, frozen)
        lo = jnp.where(f < 0, x, lo)
        hi = jnp.where(f > 0, x, hi)
        lo_untried = lo_untried & (f >= 0)
        hi_untried = hi_untried & (f <= 0)
        x_newton = x - f / df
        # Non-strict bounds: a converged iterate that sits on a bound must stay put.
        below = x_newton < lo
        above = x_newton > hi
        middle = 0.5 * (lo + hi)
        x_next = jnp.where(
            below,
            jnp.where(lo_untried, lo, middle),
            jnp.where(above, jnp.where(hi_untried, hi, middle), x_newton),
        )
        return x_next, lo, hi, lo_untried & ~below, hi_untried & ~above

    lower, upper = lax.stop_gradient((lower, upper))
    x = jnp.clip(lax.stop_gradient(x0), lower, upper)
    untried = jnp.ones(jnp.shape(x), dtype=bool)
    x, *_ = lax.fori_loop(0, n_iter, step, (x, lower, upper, untried, untried))
    f, df = residual(x, params)
    return x - f / df


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


def _perifocal_to_inertial(
    inclination: Array, raan: Array, arg_periapsis: Array
) -> Float[Array, "3 3"]:
    """Rotation matrix R3(-Ω) R1(-i) R3(-ω) from the perifocal (P, Q, W) frame (Vallado 2-88)."""
    co, so = jnp.cos(raan), jnp.sin(raan)
    ci, si = jnp.cos(inclination), jnp.sin(inclination)
    cw, sw = jnp.cos(arg_periapsis), jnp.sin(arg_periapsis)
    return jnp.array(
        [
            [co * cw - so * sw * ci, -co * sw - so * cw * ci, so * si],
            [so * cw + co * sw * ci, -so * sw + co * cw * ci, -co * si],
            [sw * si, cw * si, ci],
        ]
    )


def elements_to_state(
    elements: OrbitalElements, mu: Float[ArrayLike, ""]
) -> tuple[Float[Array, "3"], Float[Array, "3"]]:
    """Position and velocity from classical elements (Vallado algorithm 10, COE2RV).

    With p = a (1 - e²) (positive for ellipses and hyperbolas alike):
        r = p / (1 + e cos ν) (cos ν P + sin ν Q),   v = sqrt(μ/p) (-sin ν P + (e + cos ν) Q),
    where P, Q are the first two columns of R3(-Ω) R1(-i) R3(-ω). ``mu`` in length³/s².
    """
    a = jnp.asarray(elements.semi_major_axis, dtype=float)
    e = jnp.asarray(elements.eccentricity, dtype=float)
    nu = jnp.asarray(elements.true_anomaly_rad, dtype=float)
    p = a * (1.0 - e * e)
    rotation = _perifocal_to_inertial(
        jnp.asarray(elements.inclination_rad, dtype=float),
        jnp.asarray(elements.raan_rad, dtype=float),
        jnp.asarray(elements.arg_periapsis_rad, dtype=float),
    )
    cos_nu, sin_nu = jnp.cos(nu), jnp.sin(nu)
    radius = p / (1.0 + e * cos_nu)
    r_perifocal = jnp.stack([radius * cos_nu, radius * sin_nu, jnp.zeros_like(radius)])
    speed_scale = jnp.sqrt(mu / p)
    v_perifocal = jnp.stack(
        [-speed_scale * sin_nu, speed_scale * (e + cos_nu), jnp.zeros_like(radius)]
    )
    return rotation @ r_perifocal, rotation @ v_perifocal


def _unit_or(vector: Array, norm: Array, fallback: Array, is_defined: Array) -> Array:
    """vector / norm where defined, else ``fallback`` (gradient-safe: no 0/0 is ever formed)."""
    safe_norm = jnp.where(is_defined, norm, 1.0)
    return jnp.where(is_defined, vector / safe_norm, fallback)


def state_to_elements(
    r: Float[ArrayLike, "3"],
    v: Float[ArrayLike, "3"],
    mu: Float[ArrayLike, ""],
    tolerance: float = 1e-11,
) -> OrbitalElements:
    """Classical elements of a position/velocity pair (Vallado algorithm 9, RV2COE).

    h = r × v, n = ẑ × h, e = ((v² - μ/r) r - (r·v) v) / μ, a = -μ / (2 (v²/2 - μ/r)).
    The angles are taken with atan2 in the orbit plane, which stays accurate near the
    singular cases; an orbit is treated as equatorial when |n| < ``tolerance`` |h| and as
    circular when e < ``tolerance`` (see `OrbitalElements` for the conventions then).
    """
    r = jnp.asarray(r, dtype=float)
    v = jnp.asarray(v, dtype=float)
    r_norm = jnp.linalg.norm(r)
    h = jnp.cross(r, v)
    h_norm = jnp.linalg.norm(h)
    h_unit = h / h_norm
    node = jnp.array([-h[1], h[0], 0.0])
    node_norm = jnp.hypot(h[0], h[1])
    ecc_vector = ((v @ v - mu / r_norm) * r - (r @ v) * v) / mu
    e = jnp.linalg.norm(ecc_vector)
    energy = 0.5 * (v @ v) - mu / r_norm
    a = -mu / (2.0 * energy)

    inclination = jnp.arctan2(node_norm, h[2])
    node_unit = _unit_or(
        node, node_norm, jnp.array([1.0, 0.0, 0.0]), node_norm > tolerance * h_norm
    )
    raan = jnp.arctan2(node_unit[1], node_unit[0])
    periapsis_unit = _unit_or(ecc_vector, e, node_unit, e > tolerance)
    arg_periapsis = jnp.arctan2(
        h_unit @ jnp.cross(node_unit, periapsis_unit), node_unit @ periapsis_unit
    )
    true_anomaly = jnp.arctan2(h_unit @ jnp.cross(periapsis_unit, r), periapsis_unit @ r)
    two_pi = 2.0 * jnp.pi
    return OrbitalElements(
        semi_major_axis=a,
        eccentricity=e,
        inclination_rad=inclination,
        raan_rad=jnp.mod(raan, two_pi),
        arg_periapsis_rad=jnp.mod(arg_periapsis, two_pi),
        true_anomaly_rad=true_anomaly,
    )


def time_since_periapsis(
    r: Float[ArrayLike, "3"], v: Float[ArrayLike, "3"], mu: Float[ArrayLike, ""]
) -> Float[Array, ""]:
    """t - τ, time since the (nearest) periapsis passage τ, from Kepler's equation.

    Seed 001, eqs. 27-30: a from vis-viva, 1/a = 2/r - v²/μ; then e sin E = (r·v)/sqrt(μ a),
    e cos E = 1 - r/a and t - τ = (E - e sin E) / n with n = sqrt(μ/a³) for an ellipse
    (result in (-T/2, T/2]), and e sinh H = (r·v)/sqrt(-μ a), t - τ = (e sinh H - H) / n,
    n = sqrt(-μ/a³), for a hyperbola. The transfer time between two states on one conic
    (eqs. 31-32) is the difference of two such values (plus whole periods). Seconds if SI.
    """
    r = jnp.asarray(r, dtype=float)
    v = jnp.asarray(v, dtype=float)
    r_norm = jnp.linalg.norm(r)
    alpha = 2.0 / r_norm - (v @ v) / mu  # 1/a
    radial = (r @ v) / jnp.sqrt(mu)  # (r·v)/sqrt(μ)
    elliptic = alpha > 0.0
    alpha_ell = jnp.where(elliptic, alpha, 1.0)
    alpha_hyp = jnp.where(elliptic, -1.0, alpha)
    # Ellipse: E from atan2 of (e sin E, e cos E).
    e_sin_e = radial * jnp.sqrt(alpha_ell)
    ecc_anomaly = jnp.arctan2(e_sin_e, 1.0 - r_norm * alpha_ell)
    t_ell = (ecc_anomaly - e_sin_e) / jnp.sqrt(mu * alpha_ell**3)
    # Hyperbola: H from e sinh H.
    e_sinh_h = radial * jnp.sqrt(-alpha_hyp)
    e_cosh_h = 1.0 - r_norm * alpha_hyp
    hyp_anomaly = jnp.arcsinh(e_sinh_h / jnp.sqrt(e_cosh_h**2 - e_sinh_h**2))
    t_hyp = (e_sinh_h - hyp_anomaly) / jnp.sqrt(-mu * alpha_hyp**3)
    return jnp.where(elliptic, t_ell, t_hyp)


def _stumpff_series(psi: Array, first_factorial_index: int) -> Array:
    """Σ_k (-ψ)^k / (2k + j)! for j = ``first_factorial_index`` (2 for c2, 3 for c3)."""
    total = jnp.zeros_like(psi)
    term = jnp.ones_like(psi) / float(_factorial(first_factorial_index))
    for k in range(_STUMPFF_SERIES_TERMS):
        total = total + term
        j = 2 * k + first_factorial_index
        term = -term * psi / ((j + 1) * (j + 2))
    return total


def _factorial(n: int) -> int:
    return 1 if n <= 1 else n * _factorial(n - 1)


def stumpff_c2(psi: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
    """Stumpff function c2(ψ) = (1 - cos √ψ)/ψ, (cosh √-ψ - 1)/(-ψ) for ψ < 0, 1/2 at 0.

    Written as 2 sin²(√ψ/2)/ψ (resp. 2 sinh²) to avoid cancellation, and as its power series
    for |ψ| < 1 (Vallado eq. 2-52). Gradient-safe at and around ψ = 0.
    """
    psi = jnp.asarray(psi, dtype=float)
    positive = psi >= _STUMPFF_SERIES_LIMIT
    negative = psi <= -_STUMPFF_SERIES_LIMIT
    psi_pos = jnp.where(positive, psi, 1.0)
    psi_neg = jnp.where(negative, psi, -1.0)
    psi_small = jnp.where(positive | negative, 0.0, psi)
    c2_pos = 2.0 * jnp.sin(0.5 * jnp.sqrt(psi_pos)) ** 2 / psi_pos
    c2_neg = 2.0 * jnp.sinh(0.5 * jnp.sqrt(-psi_neg)) ** 2 / (-psi_neg)
    return jnp.where(positive, c2_pos, jnp.where(negative, c2_neg, _stumpff_series(psi_small, 2)))


def stumpff_c3(psi: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
    """Stumpff function c3(ψ) = (√ψ - sin √ψ)/ψ^(3/2), (sinh √-ψ - √-ψ)/(-ψ)^(3/2), 1/6 at 0.

    Power series for |ψ| < 1 (Vallado eq. 2-53). Gradient-safe at and around ψ = 0.
    """
    psi = jnp.asarray(psi, dtype=float)
    positive = psi >= _STUMPFF_SERIES_LIMIT
    negative = psi <= -_STUMPFF_SERIES_LIMIT
    sqrt_pos = jnp.sqrt(jnp.where(positive, psi, 1.0))
    sqrt_neg = jnp.sqrt(-jnp.where(negative, psi, -1.0))
    psi_small = jnp.where(positive | negative, 0.0, psi)
    c3_pos = (sqrt_pos - jnp.sin(sqrt_pos)) / sqrt_pos**3
    c3_neg = (jnp.sinh(sqrt_neg) - sqrt_neg) / sqrt_neg**3
    return jnp.where(positive, c3_pos, jnp.where(negative, c3_neg, _stumpff_series(psi_small, 3)))


def _universal_radius(chi: Array, alpha: Array, sigma0: Array, r0_norm: Array):
    """r(χ) = χ² c2 + σ0 χ (1 - ψ c3) + r0 (1 - ψ c2), ψ = α χ²; also returns χ², ψ, c2, c3."""
    chi2 = chi * chi
    psi = alpha * chi2
    c2, c3 = stumpff_c2(psi), stumpff_c3(psi)
    radius = chi2 * c2 + sigma0 * chi * (1.0 - psi * c3) + r0_norm * (1.0 - psi * c2)
    return radius, chi2, psi, c2, c3


def _universal_kepler_residual(chi: Array, params: tuple[Array, Array, Array, Array]):
    """Universal Kepler equation minus √μ Δt, and its χ-derivative r(χ).

    params = (α, σ0, r0, √μ Δt).
    """
    alpha, sigma0, r0_norm, sqrt_mu_dt = params
    radius, chi2, _, c2, c3 = _universal_radius(chi, alpha, sigma0, r0_norm)
    time_term = sigma0 * chi2 * c2 + (1.0 - alpha * r0_norm) * chi * chi2 * c3 + r0_norm * chi
    return time_term - sqrt_mu_dt, radius


def propagate_kepler(
    r0: Float[ArrayLike, "3"],
    v0: Float[ArrayLike, "3"],
    dt: Float[ArrayLike, ""],
    mu: Float[ArrayLike, ""],
    n_iter: int = UNIVERSAL_ITERATIONS,
) -> tuple[Float[Array, "3"], Float[Array, "3"]]:
    """Two-body state after ``dt`` by universal variables and Lagrange f, g (Vallado alg. 8).

    With α = 1/a = 2/r0 - v0²/μ, σ0 = r0·v0/√μ and ψ = α χ², the universal anomaly χ solves

        √μ Δt = σ0 χ² c2(ψ) + (1 - α r0) χ³ c3(ψ) + r0 χ,

    whose χ-derivative is the radius r(χ) > 0, so the root is unique; since r >= r_p it lies in
    [0, √μ Δt / r_p] (and, for a hyperbola, within the Δχ implied by the hyperbolic Kepler
    equation), which brackets the safeguarded Newton solve. Then

        f = 1 - χ² c2 / r0,  g = Δt - χ³ c3 / √μ,  ḟ = √μ χ (ψ c3 - 1) / (r r0),  ġ = 1 - χ² c2 / r,
        r = f r0 + g v0,  v = ḟ r0 + ġ v0.

    On a hyperbola the terms of both equations grow like exp|ΔH| and cancel when the arc runs
    from far out on one branch to the other (relative error ~1e-16 exp|ΔH|). A hyperbolic state
    more than 10 |a| from the focus is therefore first moved, in closed form, to periapsis
    (`time_since_periapsis`), where σ0 = 0, all terms are positive and f r_p ⟂ g v_p.

    Valid for elliptic, parabolic and hyperbolic orbits and either sign of ``dt``; not for
    rectilinear ones. Differentiable (exact first derivatives via the implicit χ).
    """
    r0 = jnp.asarray(r0, dtype=float)
    v0 = jnp.asarray(v0, dtype=float)
    dt = jnp.asarray(dt, dtype=float)
    r0_norm = jnp.linalg.norm(r0)
    alpha = 2.0 / r0_norm - (v0 @ v0) / mu
    h = jnp.cross(r0, v0)
    ecc_vector = ((v0 @ v0 - mu / r0_norm) * r0 - (r0 @ v0) * v0) / mu
    ecc = jnp.linalg.norm(ecc_vector)
    far_on_hyperbola = (alpha * r0_norm < -10.0) & (ecc > 1.0)

    # Periapsis state r_p P, v_p Q and the time from it (evaluated on safe values otherwise).
    safe_ecc = jnp.where(far_on_hyperbola, ecc, 2.0)
    safe_vector = jnp.where(far_on_hyperbola, ecc_vector, jnp.array([2.0, 0.0, 0.0]))
    h_norm = jnp.linalg.norm(h)
    periapsis_dir = safe_vector / safe_ecc
    velocity_dir = jnp.cross(h / h_norm, periapsis_dir)
    r_periapsis = h_norm**2 / (mu * (1.0 + safe_ecc))
    sqrt_mu = jnp.sqrt(mu)
    safe_r0 = jnp.where(far_on_hyperbola, r0, jnp.array([1.0, 0.0, 0.0]))
    safe_v0 = jnp.where(far_on_hyperbola, v0, jnp.array([0.1, 0.5, 0.0]) * sqrt_mu)
    since_periapsis = time_since_periapsis(safe_r0, safe_v0, mu)
    r_start = jnp.where(far_on_hyperbola, r_periapsis * periapsis_dir, r0)
    v_start = jnp.where(far_on_hyperbola, (h_norm / r_periapsis) * velocity_dir, v0)
    dt_start = jnp.where(far_on_hyperbola, dt + since_periapsis, dt)
    return _propagate_universal(r_start, v_start, dt_start, mu, n_iter)


def _propagate_universal(
    r0: Array, v0: Array, dt: Array, mu: ArrayLike, n_iter: int
) -> tuple[Array, Array]:
    """`propagate_kepler` from the given state, without the periapsis re-anchoring."""
    r0 = jnp.asarray(r0, dtype=float)
    v0 = jnp.asarray(v0, dtype=float)
    dt = jnp.asarray(dt, dtype=float)
    sqrt_mu = jnp.sqrt(mu)
    r0_norm = jnp.linalg.norm(r0)
    sigma0 = (r0 @ v0) / sqrt_mu
    alpha = 2.0 / r0_norm - (v0 @ v0) / mu
    h_squared = jnp.sum(jnp.cross(r0, v0) ** 2)
    ecc = jnp.sqrt(jnp.maximum(1.0 - alpha * h_squared / mu, 0.0))
    r_periapsis = h_squared / (mu * (1.0 + ecc))
    chi_bound = sqrt_mu * jnp.abs(dt) / r_periapsis

    # A hyperbola's χ = √(-a) ΔH, with |H| <= asinh(|M| / (e - 1)) from the hyperbolic Kepler
    # equation: a second bound that keeps cosh(√-ψ) finite on long hyperbolic arcs.
    hyperbolic = (alpha < 0.0) & (ecc > 1.0)
    alpha_h = jnp.where(hyperbolic, alpha, -1.0)
    ecc_h = jnp.where(hyperbolic, ecc, 2.0)
    hyp_anomaly0 = jnp.arcsinh(sigma0 * jnp.sqrt(-alpha_h) / ecc_h)
    mean_anomaly0 = ecc_h * jnp.sinh(hyp_anomaly0) - hyp_anomaly0
    mean_motion = sqrt_mu * (-alpha_h) ** 1.5
    max_mean_anomaly = jnp.abs(mean_anomaly0) + mean_motion * jnp.abs(dt)
    max_hyp_anomaly = jnp.arcsinh(max_mean_anomaly / (ecc_h - 1.0))
    hyp_bound = (max_hyp_anomaly + jnp.abs(hyp_anomaly0)) / jnp.sqrt(-alpha_h)
    chi_bound = jnp.where(hyperbolic, jnp.minimum(chi_bound, hyp_bound), chi_bound)

    # Mean-motion start for an ellipse (χ = √μ Δt α), circular-speed start otherwise.
    chi0 = jnp.where(alpha > 0.0, sqrt_mu * dt * alpha, sqrt_mu * dt / r0_norm)
    lower = jnp.where(dt >= 0.0, 0.0, -chi_bound)
    upper = jnp.where(dt >= 0.0, chi_bound, 0.0)
    params = (alpha, sigma0, r0_norm, sqrt_mu * dt)
    chi = _bracketed_newton(_universal_kepler_residual, params, chi0, lower, upper, n_iter)

    radius, chi2, psi, c2, c3 = _universal_radius(chi, alpha, sigma0, r0_norm)
    f = 1.0 - chi2 * c2 / r0_norm
    g = dt - chi * chi2 * c3 / sqrt_mu
    f_dot = sqrt_mu * chi * (psi * c3 - 1.0) / (radius * r0_norm)
    g_dot = 1.0 - chi2 * c2 / radius
    return f * r0 + g * v0, f_dot * r0 + g_dot * v0
