"""Bracketed Newton iteration with an implicit-function last step, shared by the Kepler
solves."""

from collections.abc import Callable

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array


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
