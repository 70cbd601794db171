"""The entry guidance family (seed 003): ``base`` (family base, on-board entry model, shared
flight variables); the skip-entry law ``skip_entry`` with its ``predictor``, ``corrector``,
``tracking``, ``phases`` (phase machine and reversals) and ``state``; the second-entry
``reference`` it tracks, with the ``nominal`` flight, the ``reach`` check, the ``design``, its
tabulation (``tabulate``) and the disk ``cache`` that make it; and the open-loop ``corridor``
and footprint tools."""

from . import skip_entry  # noqa: F401  (registration)
from .base import AbstractEntryGuidance

__all__ = ["AbstractEntryGuidance"]
