"""The capsule system (scenario kind ``capsule``): lunar-return skip entry (seed 003).

``params`` its scenario parameters (one Module per section, each field declared once;
``dispersions`` the ``[dispersions]`` section) and ``schema`` their cross-field checks,
``simulation`` one closed-loop entry (dispersed truth, bank actuator, chute crossing) and
``state`` its loop state by kind, outcome and trace,
``reference`` the second-entry reference designed for a scenario and handed to its law,
``system`` the registered contract with its cost model and statistics, ``envelope`` its
envelope pre-check (entry corridor, footprints) and ``figures`` its report figures. Its
guidance laws are the family :mod:`gnc_jax.guidance.entry`.
"""

from .system import CapsuleSystem

__all__ = ["CapsuleSystem"]
