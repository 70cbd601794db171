# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""Newton's method on a targeting problem (seed 001 eqs. 16, 18).

Newton re-propagates with the updated P, recomputes ΔQ and K, and repeats; the executed Δv is
the final P minus the initial one. The iteration runs a fixed number of times in
`lax.fori_loop` (a run that has met its tolerance keeps its P), so a batch of dispersed states
vmaps without data-dependent trip counts.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._types import Array, Float
from .problem import AbstractTargetingProblem, solve_linear_targeting
from .sensitivity import AbstractSensitivity, AutodiffSensitivity


class TargetingResult(NamedTuple):
    """Outcome of `NewtonTargeter.solve`.

    ``p``: final control; ``q``: Q at ``p``; ``q_initial``: Q at the initial control (the
    prediction before the correction); ``k``: the last sensitivity; ``iterations``: Newton
    updates applied; ``converged``: |Q(p) - Q_target| within the tolerance per component.
    """

    p: Float[Array, " m"]
    q: Float[Array, " n"]
    q_initial: Float[Array, " n"]
    k: Float[Array, "n m"]
    iterations: Array
    converged: Array


class NewtonTargeter(eqx.Module):
    """Fixed-iteration Newton targeter (module docstring).

    Attributes:
        tolerance: per-component tolerance on |Q - Q_target| (Q's units: m, s).
        sensitivity: how K is obtained (an `AbstractSensitivity`; default autodiff).
        iterations: Newton iterations (static); each evaluates Q and K once.
    """

    tolerance: Float[Array, " n"]
    sensitivity: AbstractSensitivity = eqx.field(default_factory=AutodiffSensitivity)
    iterations: int = eqx.field(static=True, default=4)

    def solve(
        self,
        problem: AbstractTargetingProblem,
        q_target: Float[Array, " n"],
        p0: Float[Array, " m"],
    ) -> TargetingResult:
        """Newton iteration P ← P + K⁻¹(Q_target - Q(P)) (generalised inverse by shape).

        Args:
            problem: P -> Q, the on-board prediction of the terminal parameters.
            q_target: the aim, Q_target.
            p0: initial control (usually zero Δv).
        """

        def within(q):
            return jnp.all(jnp.abs(q - q_target) <= self.tolerance)

        def body(i, carry):
            p, _, q_first, _, count = carry
            q, k = self.sensitivity.q_and_jacobian(problem, p)
            q_first = jnp.where(i == 0, q, q_first)
            done = within(q)
            p_next = jnp.where(done, p, p + solve_linear_targeting(k, q_target - q))
            return p_next, q, q_first, k, count + jnp.where(done, 0, 1)

        n, m = q_target.shape[0], p0.shape[0]
        init = (p0, q_target, q_target, jnp.zeros((n, m)), jnp.zeros((), jnp.int32))
        p, _, q_first, k, count = jax.lax.fori_loop(0, self.iterations, body, init)
        q = problem.q(p)
        return TargetingResult(p, q, q_first, k, count, within(q))
