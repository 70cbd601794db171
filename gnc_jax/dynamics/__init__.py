"""Equations of motion (Cartesian states, SI units)."""

from .impactor import Engine, ImpactorState, RelativeDynamics

__all__ = ["Engine", "ImpactorState", "RelativeDynamics"]
