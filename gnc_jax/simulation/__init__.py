"""Closed-loop simulators, one module per system, each written for a single trajectory."""

from . import impactor, midcourse
from .impactor import (
    ImpactorErrors,
    ImpactorOutcome,
    ImpactorSimulation,
    StepRecord,
)
from .impactor import (
    simulate as simulate_impactor,
)
from .midcourse import FixRecord, MidcourseErrors, MidcourseOutcome, MidcourseSimulation
from .midcourse import simulate as simulate_midcourse

__all__ = [
    "impactor",
    "ImpactorErrors",
    "ImpactorOutcome",
    "ImpactorSimulation",
    "StepRecord",
    "simulate_impactor",
    "midcourse",
    "FixRecord",
    "MidcourseErrors",
    "MidcourseOutcome",
    "MidcourseSimulation",
    "simulate_midcourse",
]
