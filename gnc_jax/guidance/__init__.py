"""Guidance laws: equinox Modules whose gains are differentiable leaves."""

from .base import AbstractImpactorGuidance, EngineCommand, ImpactorGuidanceContext
from .los import LOSGuidanceState, LOSSwitchingCurveGuidance, switching_curve
from .predictive import PredictiveGuidance, PredictiveGuidanceState

__all__ = [
    "AbstractImpactorGuidance",
    "EngineCommand",
    "ImpactorGuidanceContext",
    "LOSGuidanceState",
    "LOSSwitchingCurveGuidance",
    "switching_curve",
    "PredictiveGuidance",
    "PredictiveGuidanceState",
]
