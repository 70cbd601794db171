"""The midcourse system (scenario kind ``midcourse``): autonomous midcourse correction of an
Earth-Mars transfer by B-plane targeting (seed 001).

``params`` its scenario parameters (each field declared once), ``schema`` their cross-field
checks, ``build`` the simulation data of a scenario with its ``nominal`` transfer,
``simulation`` one dispersed run of navigation fixes and corrections (start, run, finish),
``partials`` the sensitivity figures along the nominal, ``system`` the registered contract
with its statistics and figures. Its guidance laws are the family
:mod:`gnc_jax.guidance.midcourse`.
"""

from .system import MidcourseSystem

__all__ = ["MidcourseSystem"]
