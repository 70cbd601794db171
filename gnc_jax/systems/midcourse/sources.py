"""The midcourse transfer's error sources and the draws each owns (:mod:`.simulation`)."""

from ..._random import INDEX
from ..base import ErrorSource
from .simulation import _EXECUTION, _INITIAL_POSITION, _INITIAL_VELOCITY, _NAVIGATION

_FIX, _BURN = (_NAVIGATION, INDEX), (_EXECUTION, INDEX)

ERROR_SOURCES = {
    "dispersion_position": ErrorSource(
        ("dispersion.position_km",), (((_INITIAL_POSITION,),),), "initial position dispersion"
    ),
    "dispersion_velocity": ErrorSource(
        ("dispersion.velocity_mps",), (((_INITIAL_VELOCITY,),),), "initial velocity dispersion"
    ),
    "nav_position": ErrorSource(
        ("navigation.position_sigma_km",), ((_FIX, 0, 3),), "navigation position noise"
    ),
    "nav_velocity": ErrorSource(
        ("navigation.velocity_sigma_mps",), ((_FIX, 3, 6),), "navigation velocity noise"
    ),
    "execution_magnitude": ErrorSource(
        ("execution.magnitude_sigma_pct",), ((_BURN, 0, 1),), "burn magnitude"
    ),
    "execution_pointing": ErrorSource(
        ("execution.pointing_sigma_deg",), ((_BURN, 1, 3),), "burn pointing"
    ),
}

SOURCE_GROUPS = {
    "dispersion": ("dispersion_position", "dispersion_velocity"),
    "navigation": ("nav_position", "nav_velocity"),
    "execution": ("execution_magnitude", "execution_pointing"),
}

BUDGET_METRICS = {
    "b_err_m": lambda o: o["b_err_m"],
    "b_err_r_m": lambda o: o["b_err_r_m"],
    "b_err_t_m": lambda o: o["b_err_t_m"],
    "dv_mps": lambda o: o["dv_mps"],
}
