# ruff: noqa: F722  (jaxtyping shape strings such as "n m" are not Python expressions)
"""How the targeter obtains K = ∂Q/∂P: the sensitivity family (one registered member per method,
chosen by ``guidance.sensitivity``).
"""

import abc
from typing import ClassVar

import equinox as eqx

from ...._types import Array, Float
from ..problem import AbstractTargetingProblem


class AbstractSensitivity(eqx.Module):
    """How the targeter obtains K = ∂Q/∂P (module docstring). Class attribute ``method_name``:
    the name a scenario chooses it by (``guidance.sensitivity``), set by
    `register_sensitivity`."""

    method_name: ClassVar[str] = ""
    propagations: ClassVar[float] = 1.0
    """Propagations to the encounter one Newton iteration costs with this method, for the
    cost model (measured by ``benchmarks/cost_midcourse_intercept.py``)."""

    @abc.abstractmethod
    def q_and_jacobian(self, problem: AbstractTargetingProblem, p: Float[Array, " m"]):
        """``(Q(p), K)`` of ``problem`` at the control ``p``."""

    @classmethod
    def from_config(cls, section: dict):
        """The method of a validated ``[guidance]`` section (SI); default: no parameters."""
        return cls()


SENSITIVITY_METHODS: dict[str, type[AbstractSensitivity]] = {}
"""The sensitivity methods by scenario name (``guidance.sensitivity``)."""


def register_sensitivity(name: str):
    """Class decorator: register a sensitivity method under ``name``."""

    def decorate(cls):
        if name in SENSITIVITY_METHODS and SENSITIVITY_METHODS[name] is not cls:
            raise ValueError(f"a sensitivity method named {name!r} is already registered")
        SENSITIVITY_METHODS[name] = cls
        cls.method_name = name
        return cls

    return decorate


def sensitivity_from_config(section: dict) -> AbstractSensitivity:
    """The sensitivity method ``section["sensitivity"]`` of a validated ``[guidance]`` section."""
    return SENSITIVITY_METHODS[section["sensitivity"]].from_config(section)
