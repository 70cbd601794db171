"""The midcourse guidance family (seed 001): ``base`` (the family base, the on-board predictor
and the transfer's targeting problem), ``problem`` (targeting problems and the linear correction,
eqs. 5-12), ``sensitivity/`` (how K = dQ/dP is obtained: one file per method), ``targeter``
(Newton's method) and one file per law (``autonomous``); importing a law's file registers it."""

from . import autonomous  # noqa: F401  (registration)
from .autonomous import AutonomousCorrection, AutonomousCorrectionState
from .base import (
    AbstractMidcourseGuidance,
    MidcourseCommand,
    MidcourseGuidanceContext,
    TransferTargetingProblem,
)
from .problem import (
    AbstractTargetingProblem,
    FunctionProblem,
    jacobian_autodiff,
    jacobian_central_difference,
    solve_linear_targeting,
)
from .sensitivity import (
    SENSITIVITIES,
    SENSITIVITY_METHODS,
    AbstractSensitivity,
    AutodiffSensitivity,
    CentralDifferenceSensitivity,
    STMSensitivity,
    register_sensitivity,
    sensitivity_from_config,
)
from .targeter import NewtonTargeter, TargetingResult

__all__ = [
    "AbstractMidcourseGuidance",
    "AbstractSensitivity",
    "AbstractTargetingProblem",
    "AutodiffSensitivity",
    "CentralDifferenceSensitivity",
    "STMSensitivity",
    "jacobian_autodiff",
    "jacobian_central_difference",
    "register_sensitivity",
    "sensitivity_from_config",
    "AutonomousCorrection",
    "AutonomousCorrectionState",
    "FunctionProblem",
    "MidcourseCommand",
    "MidcourseGuidanceContext",
    "NewtonTargeter",
    "SENSITIVITIES",
    "SENSITIVITY_METHODS",
    "TargetingResult",
    "TransferTargetingProblem",
    "solve_linear_targeting",
]
