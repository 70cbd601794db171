"""Equations of motion (Cartesian states, SI units)."""

from .heliocentric import EphemerisTable, HeliocentricModel
from .impactor import Engine, ImpactorState, RelativeDynamics

__all__ = ["Engine", "ImpactorState", "RelativeDynamics", "EphemerisTable", "HeliocentricModel"]
