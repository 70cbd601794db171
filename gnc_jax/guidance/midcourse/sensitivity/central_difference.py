# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""``"central_difference"``: seed 001 eq. 20, K_ij = (Q_i(P + ε e_j) - Q_i(P - ε e_j)) / 2ε.

The paper finds a stable range 1e-5 ≤ ε ≤ 1e2 m/s (its Fig. 1). On the packaged transfer
(periapsis 3525 km) all partials agree with autodiff to 1e-6 for 3e-5 ≤ ε ≤ 3e-4 m/s and the
B-plane ones for 1e-5 ≤ ε ≤ 0.3 m/s: below, integration noise; above, the arrival-time partials
bend (the periapsis epoch depends nonlinearly on |B| for a close flyby).
"""

import equinox as eqx
import jax.numpy as jnp

from ...._types import Scalar
from ..problem import jacobian_central_difference
from .base import AbstractSensitivity, register_sensitivity


@register_sensitivity("central_difference")
class CentralDifferenceSensitivity(AbstractSensitivity):
    """K by central differences (seed 001 eq. 20, `jacobian_central_difference`).

    Attributes:
        epsilon: the step ε, in P's units (m/s).
    """

    propagations = 7.0  # Q and six more
    epsilon: Scalar = eqx.field(default_factory=lambda: jnp.asarray(1e-3))

    def q_and_jacobian(self, problem, p):
        return jacobian_central_difference(problem.q, p, self.epsilon)

    @classmethod
    def from_config(cls, section: dict):
        return cls(epsilon=jnp.asarray(section["epsilon_mps"], dtype=jnp.float64))
