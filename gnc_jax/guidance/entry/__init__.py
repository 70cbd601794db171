"""The entry guidance family (seed 003): ``base`` (family base, on-board entry model, shared
flight variables), the skip-entry law, its reference design and the open-loop corridor and
footprint tools."""

from . import skip_entry  # noqa: F401  (registration)
from .base import AbstractEntryGuidance

__all__ = ["AbstractEntryGuidance"]
