"""Propagation by the universal-variable form of Kepler's equation (Vallado algorithm 8) and
the f and g functions (eqs. 2-58 to 2-67), with the Stumpff functions."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .elements import time_since_periapsis
from .newton import _bracketed_newton

UNIVERSAL_ITERATIONS = 30
"""Bracketed Newton steps for the universal anomaly. Over ±3000-day arcs random ellipses need
at most 8 and hyperbolas 10; near-parabolic orbits (|1 - e| < 1e-3) take a few bisection
steps first and need up to 20 (tests/geometry/test_kepler.py)."""

_STUMPFF_SERIES_LIMIT = 1.0  # |psi| below which the Stumpff functions use their series
_STUMPFF_SERIES_TERMS = 10  # (|psi| < 1: the last term is < 1 / 21! ~ 2e-20)


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
