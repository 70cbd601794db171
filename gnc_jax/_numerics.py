"""Numeric helpers shared across the package: norms and unit vectors that stay finite.

Both are written so that ``jax.grad`` is finite at the zero vector: the square root is taken of
a value that is never zero on the branch that is kept (the usual double-``where`` trick), so no
``0 * inf`` reaches the gradient of the branch that is thrown away.
"""

import jax.numpy as jnp

from ._types import Array, Float, Scalar, Vector3


def safe_norm(x: Float[Array, " n"]) -> Scalar:
    """|x|, and 0 with a zero (not NaN) gradient at x = 0 (e.g. a coasting step's zero Δv)."""
    n2 = jnp.dot(x, x)
    ok = n2 > 0.0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, n2, 1.0)), 0.0)


def smooth_norm(x: Float[Array, " n"], floor: float = 1e-12) -> Scalar:
    """sqrt(|x|^2 + floor^2): smooth everywhere and never zero, so ``x / smooth_norm(x)`` is
    finite (0 at x = 0); equal to |x| to the last bit once |x| >> floor (a Δv the predictor
    differentiates through, which may start at exactly zero)."""
    return jnp.sqrt(jnp.dot(x, x) + floor**2)


def safe_unit(v: Vector3, fallback: Vector3) -> Vector3:
    """``v/|v|``, or ``fallback`` when ``v`` is (near) zero, with finite gradients either way."""
    n2 = jnp.dot(v, v)
    ok = n2 > 1e-30
    n = jnp.sqrt(jnp.where(ok, n2, 1.0))
    return jnp.where(ok, v / n, fallback)


__all__ = ["safe_norm", "smooth_norm", "safe_unit"]
