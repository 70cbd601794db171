"""Guidance laws: equinox Modules whose gains are differentiable leaves.

Importing a law's module registers it in its family (``@register_law``); the imports below are
the registrations of the built-in laws.
"""

from .base import EngineCommand
from .entry.skip_entry import SkipEntryGuidance, SkipEntryState
from .impactor.base import AbstractImpactorGuidance, ImpactorGuidanceContext
from .impactor.los import LOSGuidanceState, LOSSwitchingCurveGuidance, switching_curve
from .impactor.pn import ProportionalNavigationGuidance as ProportionalNavigationGuidance
from .impactor.predictive import PredictiveGuidance, PredictiveGuidanceState
from .intercept.apn import APNState, AugmentedPNGuidance, PNGuidanceContext, PNNavigation
from .midcourse import (
    AutonomousCorrection,
    NewtonTargeter,
    TargetingResult,
    solve_linear_targeting,
)

__all__ = [
    "APNState",
    "AugmentedPNGuidance",
    "PNGuidanceContext",
    "PNNavigation",
    "AbstractImpactorGuidance",
    "EngineCommand",
    "ImpactorGuidanceContext",
    "LOSGuidanceState",
    "LOSSwitchingCurveGuidance",
    "switching_curve",
    "PredictiveGuidance",
    "PredictiveGuidanceState",
    "SkipEntryGuidance",
    "SkipEntryState",
    "AutonomousCorrection",
    "NewtonTargeter",
    "TargetingResult",
    "solve_linear_targeting",
]
