"""Classical orbital elements and state vectors (Vallado algorithms 9 and 10), and the time
since periapsis."""

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


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
