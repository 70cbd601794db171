"""The intercept system (scenario kind ``intercept``): deep-space intercept with variable-
coefficient augmented PN and pulse firing (seed 004).

``params`` its scenario parameters (each field declared once), ``schema`` their cross-field
checks, ``simulation`` one closed-loop run (heliocentric truth, LOS camera, packed EKF, pulse
engine), ``system`` the registered contract with its statistics and figures. Its guidance
laws are the family :mod:`gnc_jax.guidance.intercept`.
"""

from .system import InterceptSystem

__all__ = ["InterceptSystem"]
