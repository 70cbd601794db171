"""The intercept system (scenario kind ``intercept``): deep-space intercept with variable-
coefficient augmented PN and pulse firing (seed 004).

``params`` its scenario parameters (each field declared once), ``schema`` their cross-field
checks, ``build`` the simulation data of a scenario, ``simulation`` one closed-loop run (start,
run, finish) of the pieces beside it: ``state`` (the run's data, loop state, outcome and trace),
``draws`` (its random streams), ``navigation`` (LOS camera and packed EKF) and
``guidance_step`` (law, trigger, pulse engine and heliocentric truth), ``system`` the
registered contract with its statistics and figures. Its guidance laws are the family
:mod:`gnc_jax.guidance.intercept`.
"""

from .system import InterceptSystem

__all__ = ["InterceptSystem"]
