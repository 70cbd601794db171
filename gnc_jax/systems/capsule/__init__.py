"""The capsule system (scenario kind ``capsule``): lunar-return skip entry (seed 003).

``schema`` its scenario sections, ``simulation`` one closed-loop entry (dispersed truth, bank
actuator, chute crossing), ``reference`` the second-entry reference designed for a scenario and
handed to its law, ``system`` the registered contract with its statistics, envelope
pre-check and figures. Its guidance laws are the family :mod:`gnc_jax.guidance.entry`.
"""

from .system import CapsuleSystem

__all__ = ["CapsuleSystem"]
