"""Guidance laws: equinox Modules whose gains are differentiable leaves."""

from .apn import APNState, AugmentedPNGuidance, PNGuidanceContext, PNNavigation
from .base import AbstractImpactorGuidance, EngineCommand, ImpactorGuidanceContext
from .los import LOSGuidanceState, LOSSwitchingCurveGuidance, switching_curve
from .predictive import PredictiveGuidance, PredictiveGuidanceState
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
    "AutonomousCorrection",
    "NewtonTargeter",
    "TargetingResult",
    "solve_linear_targeting",
]
