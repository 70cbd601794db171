"""The impactor terminal-guidance family (seeds 000 and 002): ``base`` (family base and on-board
context) and one file per law; importing a law's file registers it."""

from . import los, pn, predictive  # noqa: F401  (registrations)
from .base import AbstractImpactorGuidance, ImpactorGuidanceContext

__all__ = ["AbstractImpactorGuidance", "ImpactorGuidanceContext"]
