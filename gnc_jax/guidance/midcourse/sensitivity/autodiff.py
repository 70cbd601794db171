# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""``"autodiff"``: K by forward-mode derivatives through the adaptive propagator itself
(`jax.jvp`; exact for the discretised map, step sizes held fixed as diffrax does).
"""

from ..problem import jacobian_autodiff
from .base import AbstractSensitivity, register_sensitivity


@register_sensitivity("autodiff")
class AutodiffSensitivity(AbstractSensitivity):
    """K by forward-mode autodiff through the propagation (`jacobian_autodiff`)."""

    propagations = 4.0  # one primal carrying three tangents

    def q_and_jacobian(self, problem, p):
        return jacobian_autodiff(problem.q, p)
