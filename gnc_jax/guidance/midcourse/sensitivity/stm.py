# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""``"stm"``: seed 001 eqs. 21-26, K = ∂Q/∂X_f · Φ(t_f, t_0) · ∂X_0/∂P from the variational
equations (`AbstractTargetingProblem.q_and_stm_jacobian`).
"""

from .base import AbstractSensitivity, register_sensitivity


@register_sensitivity("stm")
class STMSensitivity(AbstractSensitivity):
    """K from the variational equations (seed 001 eqs. 21-26): the problem's
    ``q_and_stm_jacobian``."""

    propagations = 5.0  # the 6 + 18 variational states

    def q_and_jacobian(self, problem, p):
        return problem.q_and_stm_jacobian(p)
