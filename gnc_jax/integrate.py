"""Fixed-step explicit Runge-Kutta integration inside `lax.scan`.

The closed-loop inner loops and the guidance predictors of gnc_jax integrate with a fixed step
(see README, "Integrators"): a hand-written scan is several times faster under `vmap` than
`diffrax.diffeqsolve` with a constant step, and its cost is known in advance. diffrax is kept for
adaptive long arcs, event location and as the high-accuracy reference in tests.

A vector field has the signature ``f(t, y, args) -> dy/dt`` where ``y`` is any pytree.
"""

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

VectorField = Callable[[Any, Any, Any], Any]


def _axpy(a, x, y):
    return jax.tree_util.tree_map(lambda xi, yi: yi + a * xi, x, y)


def rk4_step(f: VectorField, t, y, dt, args=None, k1=None):
    """One classical 4th-order Runge-Kutta step of size ``dt`` from ``(t, y)``.

    ``k1``: ``f(t, y, args)`` if the caller has it already (evaluated at the end of its
    previous step, "first same as last"), which saves one evaluation."""
    if k1 is None:
        k1 = f(t, y, args)
    k2 = f(t + 0.5 * dt, _axpy(0.5 * dt, k1, y), args)
    k3 = f(t + 0.5 * dt, _axpy(0.5 * dt, k2, y), args)
    k4 = f(t + dt, _axpy(dt, k3, y), args)
    return jax.tree_util.tree_map(
        lambda yi, a, b, c, d: yi + dt / 6.0 * (a + 2.0 * b + 2.0 * c + d), y, k1, k2, k3, k4
    )


class ButcherTableau:
    """Coefficients of an explicit Runge-Kutta method (numpy constants, baked in at trace time)."""

    def __init__(self, a, b, c, order: int, name: str):
        self.a = [np.asarray(row, dtype=np.float64) for row in a]
        self.b = np.asarray(b, dtype=np.float64)
        self.c = np.asarray(c, dtype=np.float64)
        self.order = order
        self.name = name
        self.stages = len(self.b)


RK4 = ButcherTableau(
    a=[[], [0.5], [0.0, 0.5], [0.0, 0.0, 1.0]],
    b=[1 / 6, 1 / 3, 1 / 3, 1 / 6],
    c=[0.0, 0.5, 0.5, 1.0],
    order=4,
    name="rk4",
)


#: Butcher's 7-stage 6th-order method (Butcher 1964; Butcher, Numerical Methods for ODEs, 2016,
#: §325): two more evaluations per step than RK4 for two more orders.
RK6_BUTCHER = ButcherTableau(
    a=[
        [],
        [1 / 3],
        [0.0, 2 / 3],
        [1 / 12, 1 / 3, -1 / 12],
        [-1 / 16, 9 / 8, -3 / 16, -3 / 8],
        [0.0, 9 / 8, -3 / 8, -3 / 4, 1 / 2],
        [9 / 44, -9 / 11, 63 / 44, 18 / 11, 0.0, -16 / 11],
    ],
    b=[11 / 120, 0.0, 27 / 40, 27 / 40, -4 / 15, -4 / 15, 11 / 120],
    c=[0.0, 1 / 3, 2 / 3, 1 / 3, 1 / 2, 1 / 2, 1.0],
    order=6,
    name="rk6",
)


def erk_step(tableau: ButcherTableau, f: VectorField, t, y, dt, args=None):
    """One step of an explicit Runge-Kutta method given by its Butcher tableau."""
    ks = []
    for i in range(tableau.stages):
        yi = y
        for j, aij in enumerate(tableau.a[i]):
            if aij != 0.0:
                yi = _axpy(dt * aij, ks[j], yi)
        ks.append(f(t + tableau.c[i] * dt, yi, args))
    out = y
    for bi, ki in zip(tableau.b, ks):
        if bi != 0.0:
            out = _axpy(dt * bi, ki, out)
    return out


def integrate_fixed(f: VectorField, t0, y0, dt, n_steps: int, args=None, tableau=RK4):
    """Integrate ``n_steps`` fixed steps of size ``dt``; returns the final state.

    ``n_steps`` is static (it fixes the trip count of the scan); ``dt`` may be traced, so the
    same compiled loop serves any arc length.
    """

    def body(carry, _):
        t, y = carry
        if tableau is RK4:
            y = rk4_step(f, t, y, dt, args)
        else:
            y = erk_step(tableau, f, t, y, dt, args)
        return (t + dt, y), None

    (_, y), _ = jax.lax.scan(body, (jnp.asarray(t0, dtype=float), y0), None, length=n_steps)
    return y
