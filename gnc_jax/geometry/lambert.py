# ruff: noqa: F722  (jaxtyping shape strings such as "" are not Python expressions)
"""Lambert's problem, zero-revolution, by Izzo's (2015) method in fixed-iteration JAX.

Given two positions and a time of flight, find the two-body conic joining them. Izzo, D.
(2015), "Revisiting Lambert's problem", Celest. Mech. Dyn. Astron. 121, 1-15, reduces every
geometry to one parameter λ and a non-dimensional time T, and solves the time-of-flight
equation T(x; λ) = T for Lancaster's variable x by Householder (third-order) iterations from an
initial guess that is already close. Here the iteration count is fixed (`LAMBERT_ITERATIONS`),
so the solver vmaps over batches of geometries without data-dependent loops, and one final
Newton step outside the loop with the iterate held constant makes first derivatives exact
(implicit-function theorem) instead of differentiating through the iteration history.

Only the zero-revolution solution is computed (it is unique). Degenerate geometries, where the
transfer plane is undefined (r1 ∥ r2: transfer angle 0 or 180°), return NaN.
"""

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float

LAMBERT_ITERATIONS = 6
"""Householder iterations. From Izzo's initial guess at most 3 reach machine precision over
transfer angles 1°-359° and T from 0.01 to 100 times the minimum-energy time (see
tests/geometry/test_lambert.py); the rest is margin."""

_BATTIN_HALF_WIDTH = 0.2  # T(x) uses Battin's series where |1 - x²| < this, x > 0
_HYPERGEOMETRIC_TERMS = 32  # |S1| <= 0.2 there: terms fall by ~0.2 each, 0.2^32 ~ 4e-23


def _hypergeometric_3_1_5half(z: Array) -> Array:
    """Gauss hypergeometric function ₂F₁(3, 1; 5/2; z) by its power series (|z| < 1).

    Term ratio t_{k+1}/t_k = (3 + k)(1 + k) / ((5/2 + k)(1 + k)) z = (3 + k)/(5/2 + k) z
    (Battin 1999, §7.3; Izzo 2015 eq. 20).
    """

    def add_term(k, carry):
        total, term = carry
        term = term * (3.0 + k) / (2.5 + k) * z
        return total + term, term

    total, _ = lax.fori_loop(
        0, _HYPERGEOMETRIC_TERMS, add_term, (jnp.ones_like(z), jnp.ones_like(z))
    )
    return total


def time_of_flight(x: Float[ArrayLike, ""], lam: Float[ArrayLike, ""]) -> Float[Array, ""]:
    """Non-dimensional zero-revolution time of flight T(x; λ), Izzo (2015) eqs. 18 and 20.

    With y = sqrt(1 - λ² (1 - x²)):
        T = (ψ / sqrt|1 - x²| - x + λ y) / (1 - x²),
        ψ = acos(x y + λ (1 - x²)) for x < 1,  ψ = asinh((y - x λ) sqrt(x² - 1)) for x > 1;
    near x = 1 (|1 - x²| < 0.2, x > 0), where that form cancels, Battin's series is used:
        η = y - λ x,  S1 = (1 - λ - x η)/2,  T = (η³ (4/3) ₂F₁(3, 1; 5/2; S1) + 4 λ η) / 2.
    Gradient-safe in both branches. x > -1, -1 <= λ <= 1.
    """
    x = jnp.asarray(x, dtype=float)
    lam = jnp.asarray(lam, dtype=float)
    one_minus_x2 = 1.0 - x * x
    battin = (jnp.abs(one_minus_x2) < _BATTIN_HALF_WIDTH) & (x > 0.0)

    # Lagrange form, evaluated at a harmless x inside the Battin band.
    x_l = jnp.where(battin, 0.0, x)
    y_l = jnp.sqrt(1.0 - lam * lam * (1.0 - x_l * x_l))
    d_l = 1.0 - x_l * x_l
    elliptic = x_l < 1.0
    cos_psi = jnp.clip(x_l * y_l + lam * d_l, -1.0, 1.0)
    psi_ell = jnp.arccos(jnp.where(elliptic, cos_psi, 0.0))
    psi_hyp = jnp.arcsinh((y_l - x_l * lam) * jnp.sqrt(jnp.where(elliptic, 2.0, -d_l)))
    psi = jnp.where(elliptic, psi_ell, psi_hyp)
    t_lagrange = (psi / jnp.sqrt(jnp.abs(d_l)) - x_l + lam * y_l) / d_l

    # Battin's series, evaluated at x = 1 outside the band.
    x_b = jnp.where(battin, x, 1.0)
    y_b = jnp.sqrt(1.0 - lam * lam * (1.0 - x_b * x_b))
    eta = y_b - lam * x_b
    s1 = 0.5 * (1.0 - lam - x_b * eta)
    q = 4.0 / 3.0 * _hypergeometric_3_1_5half(s1)
    t_battin = 0.5 * (eta**3 * q + 4.0 * lam * eta)
    return jnp.where(battin, t_battin, t_lagrange)


def _time_of_flight_derivatives(x: Array, lam: Array, t: Array) -> tuple[Array, Array, Array]:
    """dT/dx, d²T/dx², d³T/dx³ at (x, T(x)), Izzo (2015) eq. 22.

    The common factor 1/(1 - x²) is singular at x = 1 (where the numerators vanish too), so
    |1 - x²| is kept >= 1e-12 there; only the step length of one iteration is affected.
    """
    y = jnp.sqrt(1.0 - lam * lam * (1.0 - x * x))
    d = 1.0 - x * x
    d = jnp.where(jnp.abs(d) < 1e-12, jnp.where(d < 0.0, -1e-12, 1e-12), d)
    lam2, lam3 = lam * lam, lam**3
    dt = (3.0 * t * x - 2.0 + 2.0 * lam3 * x / y) / d
    ddt = (3.0 * t + 5.0 * x * dt + 2.0 * (1.0 - lam2) * lam3 / y**3) / d
    dddt = (7.0 * x * ddt + 8.0 * dt - 6.0 * (1.0 - lam2) * lam3 * lam2 * x / y**5) / d
    return dt, ddt, dddt


def _initial_guess(t: Array, lam: Array) -> Array:
    """Zero-revolution starting x, Izzo (2015) eq. 30 (middle branch as corrected in poliastro,
    poliastro/poliastro#1362: x0 = exp(ln 2 ln(T/T0) / ln(T1/T0)) - 1)."""
    t0 = jnp.arccos(lam) + lam * jnp.sqrt(1.0 - lam * lam)  # T at x = 0 (eq. 19)
    t1 = 2.0 / 3.0 * (1.0 - lam**3)  # T at x = 1 (eq. 21)
    t_safe = jnp.maximum(t, 1e-300)
    long_transfer = (t0 / t_safe) ** (2.0 / 3.0) - 1.0
    short_transfer = 2.5 * t1 / t_safe * (t1 - t) / (1.0 - lam**5) + 1.0
    # ln(T1/T0) < 0 for |λ| < 1; the branch is only used for T1 < T < T0.
    log_ratio = jnp.log(jnp.clip(t1 / t0, 1e-300, 1.0 - 1e-15))
    middle = jnp.exp(jnp.log(2.0) * jnp.log(t_safe / t0) / log_ratio) - 1.0
    return jnp.where(t >= t0, long_transfer, jnp.where(t < t1, short_transfer, middle))


def solve_lambert(
    r1: Float[ArrayLike, "3"],
    r2: Float[ArrayLike, "3"],
    tof: Float[ArrayLike, ""],
    mu: Float[ArrayLike, ""],
    prograde: Bool[ArrayLike, ""] = True,
    n_iter: int = LAMBERT_ITERATIONS,
) -> tuple[Float[Array, "3"], Float[Array, "3"]]:
    """Velocities (v1, v2) at r1 and r2 of the zero-revolution conic flown in ``tof``.

    Izzo (2015), algorithm 1 for M = 0. With c = |r2 - r1|, s = (r1 + r2 + c)/2:
        λ² = 1 - c/s (λ < 0 for transfer angles beyond 180° in the chosen sense),
        T = sqrt(2 μ / s³) tof,
    x solves T(x; λ) = T (`time_of_flight`), y = sqrt(1 - λ² (1 - x²)), and with
    γ = sqrt(μ s / 2), ρ = (r1 - r2)/c, σ = sqrt(1 - ρ²) (eq. 24)
        v_r1 = γ ((λ y - x) - ρ (λ y + x)) / r1,   v_r2 = -γ ((λ y - x) + ρ (λ y + x)) / r2,
        v_t1 = γ σ (y + λ x) / r1,                  v_t2 = γ σ (y + λ x) / r2.

    ``prograde`` (may be traced) selects the transfer whose angular momentum has a positive
    z component in the frame of r1, r2 (for heliocentric EME2000 vectors, this is the usual
    direct sense of motion); ``False`` gives the retrograde one. Units: any consistent set
    (SI: m, s, m³/s² → m/s). Transfer angles of exactly 0 or 180° return NaN.
    """
    r1 = jnp.asarray(r1, dtype=float)
    r2 = jnp.asarray(r2, dtype=float)
    tof = jnp.asarray(tof, dtype=float)
    r1_norm = jnp.linalg.norm(r1)
    r2_norm = jnp.linalg.norm(r2)
    chord = jnp.linalg.norm(r2 - r1)
    semi_perimeter = 0.5 * (r1_norm + r2_norm + chord)

    r1_unit = r1 / r1_norm
    r2_unit = r2 / r2_norm
    normal = jnp.cross(r1_unit, r2_unit)
    normal = normal / jnp.linalg.norm(normal)
    # Izzo's λ >= 0 for the short way round (angle < 180° counter-clockwise about +z); the
    # long way, or the retrograde sense, flips λ and the tangential directions.
    short_way = normal[2] >= 0.0
    sense = jnp.where(short_way == jnp.asarray(prograde), 1.0, -1.0)
    lam = sense * jnp.sqrt(jnp.clip(1.0 - chord / semi_perimeter, 0.0, 1.0))
    tangent1 = sense * jnp.cross(normal, r1_unit)
    tangent2 = sense * jnp.cross(normal, r2_unit)
    t_target = jnp.sqrt(2.0 * mu / semi_perimeter**3) * tof

    # The iteration runs on gradient-stopped copies, so autodiff never enters the loop.
    lam_frozen, t_frozen = lax.stop_gradient((lam, t_target))

    def householder_step(_, x):
        t_x = time_of_flight(x, lam_frozen)
        delta = t_x - t_frozen
        dt, ddt, dddt = _time_of_flight_derivatives(x, lam_frozen, t_x)
        # Householder's third-order step (Izzo 2015 eq. 31).
        x_next = x - delta * (dt * dt - delta * ddt / 2.0) / (
            dt * (dt * dt - delta * ddt) + dddt * delta * delta / 6.0
        )
        # Zero-revolution x lies in (-1, inf); keep a wild step from leaving that domain.
        return jnp.maximum(x_next, -1.0 + 1e-12)

    x = lax.fori_loop(0, n_iter, householder_step, _initial_guess(t_frozen, lam_frozen))
    # Implicit-function step: exact dx/dλ and dx/dT, value unchanged at convergence.
    t_x = time_of_flight(x, lam)
    dt, _, _ = _time_of_flight_derivatives(x, lam_frozen, lax.stop_gradient(t_x))
    x = x - (t_x - t_target) / dt

    y = jnp.sqrt(1.0 - lam * lam * (1.0 - x * x))
    gamma = jnp.sqrt(mu * semi_perimeter / 2.0)
    rho = (r1_norm - r2_norm) / chord
    sigma = jnp.sqrt(1.0 - rho * rho)
    v_r1 = gamma * ((lam * y - x) - rho * (lam * y + x)) / r1_norm
    v_r2 = -gamma * ((lam * y - x) + rho * (lam * y + x)) / r2_norm
    v_t = gamma * sigma * (y + lam * x)
    v1 = v_r1 * r1_unit + (v_t / r1_norm) * tangent1
    v2 = v_r2 * r2_unit + (v_t / r2_norm) * tangent2
    return v1, v2
