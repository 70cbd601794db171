"""The deep-space intercept guidance family (seed 004): ``base`` and one file per law;
importing a law's file registers it."""

from . import apn  # noqa: F401  (registration)
from .base import AbstractInterceptGuidance

__all__ = ["AbstractInterceptGuidance"]
