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

The parts: ``anomalies`` (Kepler's equation and the anomalies), ``elements`` (orbital elements
and state vectors), ``universal`` (universal-variable propagation) and ``newton`` (the
bracketed Newton solve they share).
"""

from .anomalies import (
    KEPLER_ITERATIONS,
    eccentric_anomaly_from_true,
    hyperbolic_anomaly_from_true,
    mean_anomaly_from_true,
    solve_kepler_elliptic,
    solve_kepler_hyperbolic,
    true_anomaly_from_eccentric,
    true_anomaly_from_hyperbolic,
    true_anomaly_from_mean,
)
from .elements import OrbitalElements, elements_to_state, state_to_elements, time_since_periapsis
from .universal import UNIVERSAL_ITERATIONS, propagate_kepler, stumpff_c2, stumpff_c3

__all__ = [
    "KEPLER_ITERATIONS",
    "UNIVERSAL_ITERATIONS",
    "OrbitalElements",
    "solve_kepler_elliptic",
    "solve_kepler_hyperbolic",
    "true_anomaly_from_eccentric",
    "eccentric_anomaly_from_true",
    "true_anomaly_from_hyperbolic",
    "hyperbolic_anomaly_from_true",
    "mean_anomaly_from_true",
    "true_anomaly_from_mean",
    "elements_to_state",
    "state_to_elements",
    "time_since_periapsis",
    "stumpff_c2",
    "stumpff_c3",
    "propagate_kepler",
]
