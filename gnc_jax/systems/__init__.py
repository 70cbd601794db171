"""Systems: one registered contract per kind of scenario (``systems/base.py``), one subpackage
each under the scenario kind's name (``impactor``, ``capsule``, ``midcourse``, ``intercept``),
holding the system's scenario schema, its single-run simulation and its contract.

Importing this package registers the built-in systems; :func:`register_system` adds a user's
(from their code, ``GNC_JAX_PLUGINS`` or a ``gnc_jax.plugins`` entry point).
"""

from . import capsule, impactor, intercept, midcourse  # noqa: E402, F401, I001  (registrations)
from .base import (
    AbstractSystem,
    ErrorSource,
    StepCost,
    TraceRequest,
    get_system,
    register_system,
    systems,
    tunable_leaf,
)

__all__ = [
    "AbstractSystem",
    "ErrorSource",
    "StepCost",
    "TraceRequest",
    "get_system",
    "register_system",
    "systems",
    "tunable_leaf",
]
