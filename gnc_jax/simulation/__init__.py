"""Closed-loop simulators, one module per system, each written for a single trajectory."""

from . import impactor
from .impactor import (
    ImpactorErrors,
    ImpactorOutcome,
    ImpactorSimulation,
    StepRecord,
)
from .impactor import (
    simulate as simulate_impactor,
)

__all__ = [
    "impactor",
    "ImpactorErrors",
    "ImpactorOutcome",
    "ImpactorSimulation",
    "StepRecord",
    "simulate_impactor",
]
