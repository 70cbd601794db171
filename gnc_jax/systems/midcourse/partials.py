# ruff: noqa: F722  (jaxtyping shape strings such as "e" are not Python expressions)
"""The sensitivity K = ∂Q/∂Δv along the nominal transfer by every method (seed 001 Figs. 1-3):
the report's figures of the partials against the difference step and against time."""

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._types import Array, Float
from ...dynamics.heliocentric import propagate, propagate_with_stm
from ...guidance.midcourse import (
    SENSITIVITY_METHODS,
    jacobian_autodiff,
    jacobian_central_difference,
)
from .simulation import MidcourseSimulation, sensitivity, terminal_parameters


def _full_targets(sim: MidcourseSimulation) -> MidcourseSimulation:
    """The same simulation targeting all three parameters (B_R, B_T, t)."""
    aim3 = jnp.concatenate([sim.aim[:2], jnp.zeros(1)])
    return eqx.tree_at(lambda s: s.aim, sim, aim3)


@eqx.filter_jit
def partials_vs_step(sim: MidcourseSimulation, epsilons: Float[Array, " e"]):
    """Seed 001 Fig. 1: central-difference K against the step ε, and the autodiff K.

    At the nominal state at the first fix, for Q = (B_R, B_T, t). Returns
    ``(k_central_difference [e, 3, 3], k_autodiff [3, 3])``.
    """
    sim = _full_targets(sim)
    x = jnp.concatenate([sim.r0_m, sim.v0_mps])
    q = sim.guidance_context.problem(sim.t_first_fix_s, x).q
    k_cd = jax.vmap(lambda e: jacobian_central_difference(q, jnp.zeros(3), e)[1])(epsilons)
    return k_cd, jacobian_autodiff(q, jnp.zeros(3))[1]


def q_and_stm_jacobian_fixed_epoch(sim: MidcourseSimulation, t_s, state, t_end_s):
    """(Q, K) of the paper's STM formulation taken literally: the state and Φ are integrated to
    a fixed end epoch ``t_end_s`` and Q is the two-body (B-plane, Kepler t_TOF) prediction from
    the osculating planet-relative hyperbola there (seed 001 eqs. 22-34), not at the periapsis.

    For report figures only: the osculating conic away from periapsis is not the one flown (the
    solar tide bends the approach), and as the correction epoch nears ``t_end_s``, Φ -> I and
    K -> ∂Q/∂v(t_end), which is not zero: the paper's Fig. 3 behaviour.
    """

    def q_and_k(dv):
        x, phi_v, _ = propagate_with_stm(sim.model, t_s, state.at[3:].add(dv), t_end_s)
        q_of_x = lambda y: terminal_parameters(sim, t_end_s, y)[: sim.aim.shape[0]]
        return q_of_x(x), jax.jacfwd(q_of_x)(x) @ phi_v

    return q_and_k


@eqx.filter_jit
def partials_vs_time(sim: MidcourseSimulation, epochs_s: Float[Array, " k"], epsilon, t_end_s):
    """Seed 001 Figs. 2-3: K along the nominal trajectory at each epoch, by every method.

    Returns a dict ``{method: K [k, 3, 3]}``, Q = (B_R, B_T, t), for ``autodiff``,
    ``central_difference`` (step ``epsilon``), ``stm`` (to the periapsis epoch, as in the
    targeter) and ``stm_fixed_epoch`` (the paper's formulation with the fixed end epoch
    ``t_end_s``, `q_and_stm_jacobian_fixed_epoch`).
    """
    sim = _full_targets(sim)
    x0 = jnp.concatenate([sim.r0_m, sim.v0_mps])

    methods = {
        name: cls.from_config({"epsilon_mps": epsilon}) for name, cls in SENSITIVITY_METHODS.items()
    }

    def at(t):
        x, _ = propagate(sim.model, sim.t_first_fix_s, x0, t)
        out = {name: sensitivity(sim, method, t, x)[1] for name, method in methods.items()}
        fixed = q_and_stm_jacobian_fixed_epoch(sim, t, x, t_end_s)
        out["stm_fixed_epoch"] = fixed(jnp.zeros(3))[1]
        return out

    return jax.vmap(at)(epochs_s)


__all__ = ["partials_vs_step", "partials_vs_time", "q_and_stm_jacobian_fixed_epoch"]
