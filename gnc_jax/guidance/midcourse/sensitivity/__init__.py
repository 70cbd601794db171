"""The sensitivity methods of the midcourse targeter, one file each; importing a file registers
its method (``guidance.sensitivity``)."""

from . import autodiff, central_difference, stm  # noqa: F401  (registrations)
from .autodiff import AutodiffSensitivity
from .base import (
    SENSITIVITY_METHODS,
    AbstractSensitivity,
    register_sensitivity,
    sensitivity_from_config,
)
from .central_difference import CentralDifferenceSensitivity
from .stm import STMSensitivity

SENSITIVITIES = tuple(SENSITIVITY_METHODS)
"""Names of the sensitivity methods."""

__all__ = [
    "AbstractSensitivity",
    "AutodiffSensitivity",
    "CentralDifferenceSensitivity",
    "STMSensitivity",
    "SENSITIVITIES",
    "SENSITIVITY_METHODS",
    "register_sensitivity",
    "sensitivity_from_config",
]
