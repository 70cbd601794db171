"""The midcourse guidance family (seed 001): B-plane targeting with a choice of sensitivity
method, and the autonomous-correction law."""

from . import targeting  # noqa: F401  (registrations)
from .targeting import AbstractMidcourseGuidance

__all__ = ["AbstractMidcourseGuidance"]
