# ruff: noqa: F722  (jaxtyping shape strings such as "" are not Python expressions)
"""B-plane of a planet-relative hyperbola: B_T, B_R and the linearised time of flight (seed 001).

For a state (r, v) relative to a planet of gravitational parameter μ on a hyperbola
(v² > 2μ/r), with h = r × v, e the eccentricity vector (e = |e| > 1) and p̂ = ĥ × ê:

    v∞ = sqrt(v² - 2μ/r),                      b = |h| / v∞    (= |a| sqrt(e² - 1)),
    S = ê/e + sqrt(e² - 1)/e p̂                 (incoming asymptote, true anomaly -acos(-1/e)),
    B = b S × ĥ                                 (planet → asymptote's crossing of the plane ⟂ S),
    T = S × n̂ / |S × n̂|,   R = S × T,          B_T = B·T,   B_R = B·R,

with n̂ the reference-plane normal (the ecliptic pole unless a scenario says otherwise; T then
lies in the
reference plane and R points "south" of it for a prograde approach). The linearised time of
flight t_TOF is the two-body time from the state to periapsis, by the hyperbolic Kepler equation
(seed 001 eqs. 27-32, `kepler.time_since_periapsis`): the arrival epoch is t + t_TOF.

All three are constants of two-body motion, so they can be evaluated anywhere on the approach
(seed 001 evaluates them at the end of the integration); between the event sphere and periapsis
only the solar tide changes them. When S is parallel to n̂ the T axis is undefined: the jitted
functions return NaN there and `check_hyperbolic_b_plane` raises `BPlaneError` for concrete
inputs.
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from .._types import Float, Matrix3, Scalar, Vector3
from .bplane import PARALLEL_TOLERANCE, BPlaneError, b_plane_frame
from .kepler import time_since_periapsis


class HyperbolicBPlane(NamedTuple):
    """B-plane coordinates of a hyperbolic approach (SI: m, s, m/s)."""

    b_t: Scalar
    b_r: Scalar
    t_tof: Scalar  # time from the state to periapsis (negative after periapsis)
    v_inf: Scalar  # hyperbolic excess speed
    c_bi: Matrix3  # rows S, T, R


def incoming_asymptote(
    r: Float[ArrayLike, "3"], v: Float[ArrayLike, "3"], mu: Float[ArrayLike, ""]
) -> tuple[Vector3, Vector3, Scalar]:
    """Unit incoming asymptote S, unit angular momentum ĥ and eccentricity e of a hyperbola."""
    r = jnp.asarray(r, dtype=float)
    v = jnp.asarray(v, dtype=float)
    r_norm = jnp.linalg.norm(r)
    h = jnp.cross(r, v)
    h_hat = h / jnp.linalg.norm(h)
    ecc_vector = ((v @ v - mu / r_norm) * r - (r @ v) * v) / mu
    e = jnp.linalg.norm(ecc_vector)
    e_hat = ecc_vector / e
    s = (e_hat + jnp.sqrt(e * e - 1.0) * jnp.cross(h_hat, e_hat)) / e
    return s, h_hat, e


def b_plane_hyperbolic(
    r: Float[ArrayLike, "3"],
    v: Float[ArrayLike, "3"],
    mu: Float[ArrayLike, ""],
    ref_normal: Float[ArrayLike, "3"],
) -> HyperbolicBPlane:
    """B_T, B_R, t_TOF and v∞ of a planet-relative hyperbolic state (module equations).

    Args:
        r, v: position (m) and velocity (m/s) relative to the planet.
        mu: planet's gravitational parameter, m³/s².
        ref_normal: normal of the reference plane (any length), same frame as r and v.
    """
    r = jnp.asarray(r, dtype=float)
    v = jnp.asarray(v, dtype=float)
    s, h_hat, _ = incoming_asymptote(r, v, mu)
    v_inf = jnp.sqrt(v @ v - 2.0 * mu / jnp.linalg.norm(r))
    b_vector = (jnp.linalg.norm(jnp.cross(r, v)) / v_inf) * jnp.cross(s, h_hat)
    c_bi = b_plane_frame(s, jnp.asarray(ref_normal, dtype=float))
    t_tof = -time_since_periapsis(r, v, mu)
    return HyperbolicBPlane(c_bi[1] @ b_vector, c_bi[2] @ b_vector, t_tof, v_inf, c_bi)


def check_hyperbolic_b_plane(r, v, mu, ref_normal) -> None:
    """Raise `BPlaneError` with a clear message when the B-plane of (r, v) is undefined:
    not a hyperbola, or S parallel to the reference normal (concrete inputs only)."""
    r = np.asarray(r, dtype=float)
    v = np.asarray(v, dtype=float)
    n = np.asarray(ref_normal, dtype=float)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(v))):
        raise BPlaneError("B-plane: the planet-relative state must be finite")
    energy = 0.5 * v @ v - mu / np.linalg.norm(r)
    if not energy > 0.0:
        raise BPlaneError(
            f"B-plane: the planet-relative orbit is not a hyperbola (energy {energy:.3g} J/kg)"
        )
    if np.linalg.norm(n) == 0.0:
        raise BPlaneError("B-plane: the reference-plane normal must be non-zero")
    s = np.asarray(incoming_asymptote(r, v, mu)[0])
    if np.linalg.norm(np.cross(s, n)) <= PARALLEL_TOLERANCE * np.linalg.norm(n):
        raise BPlaneError(
            "B-plane: the incoming asymptote S is parallel to the reference-plane normal, "
            "so the T axis (S x n) is undefined; choose another reference plane"
        )
