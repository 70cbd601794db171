"""Error budgets: which error source drives each metric, by pick-freeze Sobol indices, one
source at a time and linearisation (:func:`budget`)."""

from .engine import METHODS, budget, budget_cost
from .result import Budget, format_table

__all__ = ["METHODS", "Budget", "budget", "budget_cost", "format_table"]
