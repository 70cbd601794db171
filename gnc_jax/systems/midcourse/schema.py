"""Scenario fields of the autonomous midcourse correction (seed 001).

File units follow the paper (km, m/s, days, %, deg; epochs as TDB calendar strings) and are
converted to SI when the simulation is built; the field names carry the units. Vectors are in
the heliocentric EME2000 axes (the paper's "x axis" is EME2000 x).
"""

import math

from ... import time as gtime
from ...constants import SECONDS_PER_DAY
from ...schema import Field, ScenarioError

F = Field

SCHEMA = {
    "mission": {
        "launch_epoch": F(
            "str",
            "2007-08-04",
            units="TDB",
            doc="Earth departure of the nominal Lambert transfer (Phoenix's launch date)",
        ),
        "encounter_epoch": F(
            "str",
            "2008-04-26",
            units="TDB",
            doc="nominal Mars periapsis epoch (the paper's end date: 2007-09-01 is E-238 d)",
        ),
        "first_fix_epoch": F(
            "str",
            "2007-09-01",
            units="TDB",
            doc="first navigation fix and correction opportunity (the paper's E-238 d)",
        ),
        "aim_b_km": F(
            "floats",
            [4200.0, -4200.0],
            length=2,
            lo=-1e6,
            hi=1e6,
            units="km",
            doc="aim point (B_T, B_R) at Mars; |B| = 5940 km puts periapsis at 3525 km",
        ),
        "reference_plane": F(
            "str",
            "ecliptic",
            choices=("ecliptic", "equator", "mars_orbit"),
            doc="B-plane reference plane: T = S x n with n its normal (J2000 ecliptic pole, "
            "EME2000 pole or Mars's orbit normal at encounter)",
        ),
    },
    "spacecraft": {
        "mass_kg": F("float", 664.0, lo=0.0, lo_open=True, hi=1e5, units="kg"),
        "srp_area_m2": F(
            "float", 7.0, lo=0.0, hi=1e4, units="m^2", doc="cannonball cross-section for SRP"
        ),
        "reflectivity": F(
            "float", 1.3, lo=0.0, hi=2.0, doc="radiation-pressure coefficient C_r (1: absorbing)"
        ),
    },
    "dynamics": {
        "solver": F(
            "str",
            "dopri8",
            choices=("dopri8", "dopri5", "tsit5"),
            doc="adaptive Runge-Kutta pair (the paper: dopri5, a 4(5) pair)",
        ),
        "rtol": F("float", 1e-13, lo=1e-15, hi=1e-6, doc="relative integration tolerance"),
        "atol": F(
            "float", 1e-7, lo=0.0, lo_open=True, hi=1e3, units="m, m/s", doc="absolute tolerance"
        ),
        "max_steps": F("int", 4096, lo=16, hi=1_000_000, doc="integrator step budget per arc"),
        "planets": F("bool", True, doc="the 8 planets as point-mass perturbations"),
        "ephemeris": F(
            "str",
            "table",
            choices=("table", "plan94"),
            doc="planet positions: quintic Hermite table of plan94 at 1-day nodes (error < 1 m) "
            "or plan94 evaluated at every integrator stage (~5x slower)",
        ),
        "srp": F("bool", True, doc="solar radiation pressure (cannonball)"),
        "window_days": F(
            "float",
            30.0,
            lo=0.0,
            lo_open=True,
            hi=1000.0,
            units="days",
            doc="search for the closest approach up to this long after the nominal encounter",
        ),
    },
    "navigation": {
        "fixes": F(
            "int",
            1,
            lo=1,
            hi=1000,
            doc="navigation fixes (correction opportunities), the first at first_fix_epoch",
        ),
        "interval_days": F(
            "float", 7.0, lo=0.0, lo_open=True, hi=1000.0, units="days", doc="fix interval"
        ),
    },
    "guidance": {
        "enabled": F("bool", True, doc="false: no correction (the paper's Table 1 dispersion)"),
        "targets": F(
            "str",
            "b_plane_tof",
            choices=("b_plane_tof", "b_plane"),
            doc="Q = (B_R, B_T, t_TOF) (fixed arrival, n = m = 3) or (B_R, B_T) (free arrival, "
            "minimum-norm Δv)",
        ),
    },
    "goal": {
        "b_km": F(
            "float", 10.0, lo=0.0, lo_open=True, hi=1e7, units="km", doc="goal on |dB| (paper)"
        ),
        "tof_s": F(
            "float", 60.0, lo=0.0, lo_open=True, hi=1e8, units="s", doc="goal on |dt| (paper)"
        ),
    },
}


def epochs_s(cfg: dict) -> dict[str, float]:
    """The mission epochs in seconds past J2000 TDB (fields already validated by `check`)."""
    m = cfg["mission"]
    return {
        key: gtime.parse_epoch(m[key])
        for key in ("launch_epoch", "encounter_epoch", "first_fix_epoch")
    }


def fix_epochs_s(cfg: dict) -> list[float]:
    """Epochs of the navigation fixes, seconds past J2000 TDB."""
    t0 = epochs_s(cfg)["first_fix_epoch"]
    nav = cfg["navigation"]
    return [t0 + i * nav["interval_days"] * SECONDS_PER_DAY for i in range(nav["fixes"])]


def check(cfg: dict) -> None:
    """Cross-field checks of a validated midcourse configuration."""
    m = cfg["mission"]
    for key in ("launch_epoch", "encounter_epoch", "first_fix_epoch"):
        try:
            gtime.parse_epoch(m[key])
        except ValueError as error:
            raise ScenarioError(
                f"mission.{key}: {error}; allowed: a TDB date YYYY-MM-DD[THH:MM[:SS]] "
                "within 1900-2100"
            ) from None
        year = int(m[key][:4])
        if not 1900 <= year <= 2100:
            raise ScenarioError(
                f"mission.{key}: {m[key]!r} is outside the ephemeris' span; "
                "allowed: years 1900-2100"
            )
    t = epochs_s(cfg)
    if not t["launch_epoch"] < t["first_fix_epoch"] < t["encounter_epoch"]:
        raise ScenarioError(
            f"mission.first_fix_epoch: {m['first_fix_epoch']!r}; allowed: after "
            f"launch_epoch ({m['launch_epoch']}) and before encounter_epoch "
            f"({m['encounter_epoch']})"
        )
    last = fix_epochs_s(cfg)[-1]
    if not last < t["encounter_epoch"] - SECONDS_PER_DAY:
        days = (t["encounter_epoch"] - t["first_fix_epoch"]) / SECONDS_PER_DAY
        nav = cfg["navigation"]
        raise ScenarioError(
            f"navigation.fixes: {nav['fixes']} fixes every {nav['interval_days']:g} days end "
            f"{(last - t['encounter_epoch']) / SECONDS_PER_DAY:+.1f} days from encounter; "
            "allowed: the "
            f"last fix at least 1 day before encounter, i.e. (fixes - 1) * interval_days < "
            f"{days - 1.0:g}"
        )
    if math.hypot(*m["aim_b_km"]) == 0.0:
        raise ScenarioError(
            "mission.aim_b_km: (0, 0) aims at the planet's centre (rectilinear, no B-plane); "
            "allowed: a non-zero (B_T, B_R)"
        )
