"""Scenarios: packaged TOML files and user files, validated before anything is compiled."""

from ..schema import Field, ScenarioError
from .loader import Scenario, list_scenarios, load_scenario, packaged_names

__all__ = [
    "Field",
    "Scenario",
    "ScenarioError",
    "list_scenarios",
    "load_scenario",
    "packaged_names",
]
