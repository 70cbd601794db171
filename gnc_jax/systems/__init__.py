"""Systems: one registered contract per kind of scenario (``systems/base.py``), one file each
(``impactor``, ``capsule``, ``midcourse``, ``intercept``).

The built-in systems register themselves the first time the registry is asked
(:func:`get_system`, :func:`systems`); :func:`register_system` adds a user's.
"""

from .base import AbstractSystem, get_system, register_system, systems, tunable_leaf

__all__ = ["AbstractSystem", "get_system", "register_system", "systems", "tunable_leaf"]
