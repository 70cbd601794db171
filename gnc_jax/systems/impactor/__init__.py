"""The impactor system (scenario kind ``impactor``): a small-body impactor's terminal phase
(seeds 000 and 002).

``params`` its scenario fields and ``errors`` its error sources (each declared once, with
its SI value), ``schema`` their cross-field checks, ``build`` the simulation data of a
scenario, ``simulation`` one closed-loop run (truth, camera, EKF, guidance, engine) from its
``state`` types, ``draws`` (the random streams), ``navigation`` (camera, EKF update,
accelerometer) and ``step`` (the image and control steps), ``system`` the registered
contract with its statistics and figures. Its guidance laws are the family
:mod:`gnc_jax.guidance.impactor`.
"""

from .system import ImpactorSystem

__all__ = ["ImpactorSystem"]
