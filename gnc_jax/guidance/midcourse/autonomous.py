# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""The autonomous midcourse-correction law (seed 001 §3), the family's member
``"autonomous"``: Newton B-plane targeting at each fix, with the paper's thresholds.
"""

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from ..._types import Array, Float, Scalar, State6
from ...params import from_config, param
from ...schema import ScenarioError
from ..base import register_law
from .base import AbstractMidcourseGuidance, MidcourseCommand, MidcourseGuidanceContext
from .sensitivity import SENSITIVITIES, SENSITIVITY_METHODS
from .targeter import NewtonTargeter, TargetingResult


class AutonomousCorrectionState(NamedTuple):
    """The autonomous correction keeps nothing between fixes: each one is decided afresh."""


@register_law("autonomous")
class AutonomousCorrection(AbstractMidcourseGuidance):
    """The on-board decision of seed 001 §3, step 2, around a `NewtonTargeter`.

    With ΔQ the predicted error at a navigation fix, |ΔB| = hypot(ΔB_R, ΔB_T) and |Δt| the
    arrival-time error (fixed-arrival targeting only): below the lower thresholds nothing is
    done; beyond an upper threshold the error is outside the autonomous system's authority and
    is flagged for the ground (no burn); in between the targeter's Δv is executed.

    Its scenario table ``[guidance.autonomous]`` holds the targeter's settings (sensitivity
    method and its step, Newton iterations and tolerances) and the two thresholds; the
    targeter and the threshold pairs are assembled from those leaves (``targeter``, ``lower``,
    ``upper``).
    """

    sensitivity: str = param(
        "autodiff",
        choices=SENSITIVITIES,
        doc="sensitivity matrix K: forward-mode autodiff, central difference (eq. 20) or "
        "variational state-transition matrix (eqs. 21-26)",
    )
    epsilon_mps: Scalar = param(
        1e-3,
        lo=0.0,
        lo_open=True,
        hi=1e3,
        units="m/s",
        doc="central-difference step (stable region measured: 3e-5 to 5e-4 m/s for all "
        "partials to 1e-6; 1e-4 to 1 for the B partials)",
    )
    iterations: int = param(5, lo=1, hi=50, doc="Newton iterations (fixed count, masked)")
    tolerance_b_m: Scalar = param(
        0.1,
        toml="tolerance_b_km",
        scale=1e3,
        lo=0.0,
        lo_open=True,
        hi=1e6,
        units="km",
        doc="Newton tolerance on B",
    )
    tolerance_tof_s: Scalar = param(
        1.0, lo=0.0, lo_open=True, hi=1e6, units="s", doc="Newton tolerance on the arrival time"
    )
    lower_b_m: Scalar = param(
        10.0,
        toml="lower_b_km",
        scale=1e3,
        lo=0.0,
        hi=1e7,
        units="km",
        doc="lower threshold: no burn while |dB| and (fixed arrival) |dt| are below it",
    )
    lower_tof_s: Scalar = param(60.0, lo=0.0, hi=1e8, units="s", doc="lower threshold on dt")
    upper_b_m: Scalar = param(
        1e6,
        toml="upper_b_km",
        scale=1e3,
        lo=0.0,
        lo_open=True,
        hi=1e9,
        units="km",
        doc="upper threshold: beyond it the error is flagged for the ground, no burn",
    )
    upper_tof_s: Scalar = param(
        1e7, lo=0.0, lo_open=True, hi=1e10, units="s", doc="upper threshold on dt"
    )
    n_targets: int = eqx.field(static=True, default=3)  # dim Q: 3 fixed, 2 free arrival

    @property
    def lower(self) -> Float[Array, "2"]:
        """(|ΔB| in m, |Δt| in s) lower thresholds."""
        return jnp.stack([self.lower_b_m, self.lower_tof_s])

    @property
    def upper(self) -> Float[Array, "2"]:
        """(|ΔB| in m, |Δt| in s) upper thresholds."""
        return jnp.stack([self.upper_b_m, self.upper_tof_s])

    @property
    def targeter(self) -> NewtonTargeter:
        """The Newton targeter of these settings."""
        tolerance = jnp.stack([self.tolerance_b_m, self.tolerance_b_m, self.tolerance_tof_s])
        method = SENSITIVITY_METHODS[self.sensitivity]
        return NewtonTargeter(
            tolerance=tolerance[: self.n_targets],
            sensitivity=method.from_config({"epsilon_mps": self.epsilon_mps}),
            iterations=self.iterations,
        )

    def solve(self, problem, aim) -> TargetingResult:
        """The targeter's Newton solution of ``problem`` toward ``aim``, from zero Δv."""
        return self.targeter.solve(problem, aim, jnp.zeros(3))

    @classmethod
    def propagations_per_fix(cls, section: dict) -> float:
        """Newton iterations times the sensitivity method's propagations, plus the last
        prediction."""
        return (
            section["iterations"] * SENSITIVITY_METHODS[section["sensitivity"]].propagations + 1.0
        )

    @classmethod
    def check(cls, section, config):
        for lower, upper in (("lower_b_km", "upper_b_km"), ("lower_tof_s", "upper_tof_s")):
            if section[lower] >= section[upper]:
                raise ScenarioError(
                    f"guidance.autonomous.{lower}: {section[lower]:g} >= {upper} = "
                    f"{section[upper]:g}; allowed: lower < upper"
                )

    def decide(self, dq: Float[Array, " n"]) -> tuple[Array, Array]:
        """``(correct, ground)`` flags for the predicted error ``dq`` = Q - Q_target."""
        miss = jnp.stack([jnp.hypot(dq[0], dq[1]), jnp.abs(dq[2]) if dq.shape[0] > 2 else 0.0])
        below = jnp.all(miss < self.lower)
        ground = jnp.any(miss > self.upper)
        return ~below & ~ground, ground

    def init(self, nav, ctx) -> AutonomousCorrectionState:
        return AutonomousCorrectionState()

    def step(
        self, state, nav: State6, t, ctx: MidcourseGuidanceContext
    ) -> tuple[MidcourseCommand, AutonomousCorrectionState]:
        """Predict Q from the navigated state ``nav`` at ``t``, decide, and target the Δv."""
        result = self.targeter.solve(ctx.problem(t, nav), ctx.aim, jnp.zeros(3))
        dq = result.q_initial - ctx.aim
        correct, ground = self.decide(dq)
        burn = correct & result.converged
        command = MidcourseCommand(
            dv_mps=jnp.where(burn, result.p, 0.0),
            dv_targeted_mps=result.p,
            predicted_dq=dq,
            burn=burn,
            ground=ground,
            converged=result.converged,
            iterations=result.iterations,
            no_convergence=correct & ~result.converged,
        )
        return command, state

    @classmethod
    def from_config(cls, section: dict, config: dict, ctx: MidcourseGuidanceContext | None = None):
        """The law of a validated ``[guidance.autonomous]`` table (SI); ``ctx`` (required)
        gives the number of targeted parameters."""
        return from_config(cls, section, n_targets=int(ctx.aim.shape[0]))
