# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""The midcourse guidance family (seed 001 §3): its base (`AbstractMidcourseGuidance`), what a
law is handed at each navigation fix (the on-board predictor, `MidcourseGuidanceContext`, and
the transfer's targeting problem) and what it commands.
"""

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._types import Array, Float, Scalar, State6, Vector3
from ...dynamics.heliocentric import (
    HeliocentricModel,
    propagate_to_encounter,
    propagate_to_encounter_with_stm,
    relative_state,
)
from ...geometry.hyperbola import b_plane_hyperbolic
from ..base import AbstractGuidanceLaw
from .problem import AbstractTargetingProblem


class MidcourseGuidanceContext(eqx.Module):
    """The on-board predictor of the midcourse laws: force model, aim and B-plane frame.

    Attributes:
        model: heliocentric force model and integrator.
        aim: Q_target = (B_R, B_T[, 0]) in m (and s, relative to ``t_encounter_s``).
        ref_normal: B-plane reference-plane normal (EME2000).
        t_encounter_s: nominal periapsis epoch (the arrival-time target).
        t_max_s: end of the window in which the closest approach is searched.
    """

    model: HeliocentricModel
    aim: Float[Array, " n"]
    ref_normal: Vector3
    t_encounter_s: Scalar
    t_max_s: Scalar

    def terminal_parameters(self, t_s, state: State6) -> Float[Array, "3"]:
        """(B_R, B_T, t_arrival - t_encounter) of a heliocentric state near the encounter.

        The arrival time is the epoch plus the linearised time of flight to periapsis (seed 001
        eqs. 27-32); all components are planet-relative two-body constants
        (`geometry.hyperbola`). The targeted Q is the first n = ``aim.shape[0]`` components.
        """
        r_rel, v_rel = relative_state(self.model, t_s, state)
        bp = b_plane_hyperbolic(r_rel, v_rel, self.model.gm_target, self.ref_normal)
        return jnp.stack([bp.b_r, bp.b_t, (t_s - self.t_encounter_s) + bp.t_tof])

    def predict(self, t_s, state: State6) -> tuple[Float[Array, "3"], Array]:
        """``(terminal parameters, status)`` of the trajectory through ``state`` at ``t_s``."""
        enc = propagate_to_encounter(self.model, t_s, state, self.t_max_s)
        return self.terminal_parameters(enc.t_s, enc.state), enc.status

    def problem(self, t_s, state: State6) -> "TransferTargetingProblem":
        """The targeting problem of a Δv applied to ``state`` at ``t_s``."""
        return TransferTargetingProblem(self, t_s, state)


class TransferTargetingProblem(AbstractTargetingProblem):
    """P = Δv (m/s, EME2000) applied at ``t_s`` to ``state`` -> Q = the first n terminal
    parameters of `MidcourseGuidanceContext.predict`."""

    ctx: MidcourseGuidanceContext
    t_s: Scalar
    state: State6

    def q(self, p):
        n = self.ctx.aim.shape[0]
        return self.ctx.predict(self.t_s, self.state.at[3:].add(p))[0][:n]

    def q_and_stm_jacobian(self, p):
        """K = ∂Q/∂X_f Φ(t_f, t) ∂X/∂Δv (seed 001 eq. 22) from the variational equations;
        ∂Q/∂X_f is the derivative of the closed-form B-plane formulas at fixed t_f."""
        ctx = self.ctx
        enc, phi_v = propagate_to_encounter_with_stm(
            ctx.model, self.t_s, self.state.at[3:].add(p), ctx.t_max_s
        )
        q_of_x = lambda x: ctx.terminal_parameters(enc.t_s, x)[: ctx.aim.shape[0]]
        return q_of_x(enc.state), jax.jacfwd(q_of_x)(enc.state) @ phi_v


class MidcourseCommand(NamedTuple):
    """What a midcourse law decides at one navigation fix."""

    dv_mps: Vector3  # commanded Δv (zero: no burn), EME2000
    dv_targeted_mps: Vector3  # the targeter's Δv before the decision (the Δv baseline)
    predicted_dq: Float[Array, " n"]  # on-board Q - Q_target before the decision
    burn: Array  # a burn is commanded
    ground: Array  # the error is flagged for the ground
    converged: Array  # the targeter met its tolerance
    iterations: Array  # int, Newton updates applied
    no_convergence: Array  # a correction was needed but the targeter did not converge


class AbstractMidcourseGuidance(AbstractGuidanceLaw):
    """Family base of the midcourse-correction laws: ``nav`` is the navigated heliocentric
    state (r, v) at a fix, ``ctx`` a `MidcourseGuidanceContext`, ``step`` runs once per
    navigation fix and returns a `MidcourseCommand`."""

    laws: ClassVar[dict[str, type]] = {}

    @classmethod
    def propagations_per_fix(cls, section: dict) -> float:
        """Propagations to the encounter one call of the law costs, from its validated
        ``[guidance.<law>]`` section (the system's cost model); default one."""
        return 1.0
