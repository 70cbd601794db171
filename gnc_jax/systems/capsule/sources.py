"""The capsule's dispersions as error sources (:class:`.dispersions.CapsuleDispersions`) and
the draws each owns (:func:`.simulation.dispersed_entry`)."""

from ..base import ErrorSource
from .simulation import _ENTRY, _MASS


def _entry(field: str, i: int, doc: str) -> ErrorSource:
    return ErrorSource((f"dispersions.{field}",), (((_ENTRY,), i, i + 1),), doc)


ERROR_SOURCES = {
    "speed": _entry("speed_mps", 0, "entry speed"),
    "fpa": _entry("fpa_deg", 1, "entry flight-path angle"),
    "heading": _entry("heading_deg", 2, "entry heading"),
    "downrange": _entry("downrange_km", 3, "entry point downrange"),
    "altitude": _entry("altitude_km", 4, "entry altitude"),
    "crossrange": _entry("crossrange_km", 5, "entry point crossrange"),
    "lift": _entry("cl_pct", 6, "lift coefficient"),
    "drag": _entry("cd_pct", 7, "drag coefficient"),
    "density": _entry("density_pct", 8, "atmospheric density"),
    "mass": ErrorSource(("dispersions.mass_pct",), (((_MASS,),),), "mass"),
}

SOURCE_GROUPS = {
    "entry_state": ("speed", "fpa", "heading", "downrange", "altitude", "crossrange"),
    "aerodynamics": ("lift", "drag"),
}

BUDGET_METRICS = {
    "downrange_err_km": lambda o: o["downrange_err_km"],
    "crossrange_err_km": lambda o: o["crossrange_err_km"],
    "load_peak_g": lambda o: o["load_peak_g"],
}
