# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""Targeting problems and the linear correction of seed 001 §2.

The terminal parameters Q (B_R, B_T and optionally the arrival epoch) depend on the control
P (the impulsive Δv) through the propagation. Linearising about the current P (seed 001 eq. 5),

    ΔQ = K ΔP,   K = ∂Q/∂P,

gives the correction ΔP by one of (eqs. 6-12), m = dim P, n = dim Q:

    n = m:  ΔP = K⁻¹ ΔQ;
    n > m:  ΔP = (KᵀK)⁻¹ Kᵀ ΔQ          (least squares: minimises |ΔQ - K ΔP|);
    n < m:  ΔP = Kᵀ (K Kᵀ)⁻¹ ΔQ         (minimum norm: the smallest ΔP that meets ΔQ).

What is targeted is a *targeting problem* (`AbstractTargetingProblem`): P -> Q, and for the STM
method P -> (Q, K) from the variational equations; K by autodiff or central differences is
computed here for any P -> Q function.
"""

import abc
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._types import Array, Float

QFunction = Callable[[Float[Array, " m"]], Float[Array, " n"]]
QJacobianFunction = Callable[[Float[Array, " m"]], tuple[Float[Array, " n"], Float[Array, "n m"]]]


def solve_linear_targeting(k: Float[Array, "n m"], dq: Float[Array, " n"]) -> Float[Array, " m"]:
    """ΔP of the linear model ΔQ = K ΔP (seed 001 eqs. 6, 9, 12): inverse, least squares or
    minimum norm according to the (static) shape of K."""
    n, m = k.shape
    if n == m:
        return jnp.linalg.solve(k, dq)
    if n > m:
        return jnp.linalg.solve(k.T @ k, k.T @ dq)
    return k.T @ jnp.linalg.solve(k @ k.T, dq)


def jacobian_autodiff(q_fn: QFunction, p: Float[Array, " m"]):
    """``(Q(p), ∂Q/∂P)`` by forward-mode automatic differentiation through ``q_fn``.

    One primal propagation carries the m tangents (`jax.jvp` vmapped over the unit vectors).
    """
    m = p.shape[0]
    push = lambda tangent: jax.jvp(q_fn, (p,), (tangent,))
    q, k = jax.vmap(push, out_axes=(None, 1))(jnp.eye(m, dtype=p.dtype))
    return q, k


def jacobian_central_difference(q_fn: QFunction, p: Float[Array, " m"], epsilon):
    """``(Q(p), K)`` with K by central differences of step ``epsilon`` (seed 001 eq. 20).

    The 2m perturbed propagations and the nominal one run as one vmapped batch.
    """
    m = p.shape[0]
    steps = epsilon * jnp.concatenate([jnp.eye(m), -jnp.eye(m), jnp.zeros((1, m))])
    qs = jax.vmap(q_fn)(p + steps)
    k = (qs[:m] - qs[m : 2 * m]).T / (2.0 * epsilon)
    return qs[-1], k


class AbstractTargetingProblem(eqx.Module):
    """What a targeter solves: the map P -> Q and, for `STMSensitivity`, (Q, K) from the
    variational equations."""

    @abc.abstractmethod
    def q(self, p: Float[Array, " m"]) -> Float[Array, " n"]: ...

    def q_and_stm_jacobian(self, p: Float[Array, " m"]):
        """``(Q(p), K)`` with K from the variational equations (seed 001 eqs. 21-26)."""
        raise ValueError(f"{type(self).__name__} has no variational equations (STMSensitivity)")


class FunctionProblem(AbstractTargetingProblem):
    """A targeting problem given as functions: ``q_fn`` P -> Q and optionally
    ``q_and_stm_jacobian_fn`` P -> (Q, K) (closed-form maps, tests)."""

    q_fn: QFunction
    q_and_stm_jacobian_fn: QJacobianFunction | None = None

    def q(self, p):
        return self.q_fn(p)

    def q_and_stm_jacobian(self, p):
        if self.q_and_stm_jacobian_fn is None:
            return super().q_and_stm_jacobian(p)
        return self.q_and_stm_jacobian_fn(p)
