"""Guidance laws: equinox Modules whose gains are differentiable leaves.

Importing a law's module registers it in its family (``@register_law``); the imports below are
the registrations of the built-in laws.
"""

from .apn import APNState, AugmentedPNGuidance, PNGuidanceContext, PNNavigation
from .base import AbstractImpactorGuidance, EngineCommand, ImpactorGuidanceContext
from .los import LOSGuidanceState, LOSSwitchingCurveGuidance, switching_curve
from .pn import ProportionalNavigationGuidance as ProportionalNavigationGuidance
from .predictive import PredictiveGuidance, PredictiveGuidanceState
from .skip_entry import SkipEntryGuidance, SkipEntryState
from .targeting import AutonomousCorrection, NewtonTargeter, TargetingResult, solve_linear_targeting

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
