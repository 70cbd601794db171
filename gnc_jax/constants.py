"""Physical constants and unit definitions, written once (SI units).

Scenario parameters that a paper fixes (a target's GM, the Sun's GM of seed 004) are scenario
fields with their defaults in the schema, not constants.
"""

AU_M = 1.495978707e11
"""Astronomical unit, m (IAU 2012 Resolution B2)."""

GM_SUN_M3S2 = 1.32712440018e20
"""Heliocentric gravitational constant, m^3/s^2 (IERS/DE405 value)."""

G0_MPS2 = 9.80665
"""Standard gravity, m/s^2: the unit of specific impulse, of accelerometer "g" and of the sensed
entry load N_g."""

EARTH_GM_M3S2 = 3.986004418e14
"""Earth's gravitational constant, m^3/s^2 (WGS 84)."""

EARTH_EQUATORIAL_RADIUS_M = 6378137.0
"""Earth's equatorial radius, m (WGS 84)."""

SECONDS_PER_DAY = 86400.0
"""Seconds in a day of the TDB time scale (no leap seconds)."""

__all__ = [
    "AU_M",
    "GM_SUN_M3S2",
    "G0_MPS2",
    "EARTH_GM_M3S2",
    "EARTH_EQUATORIAL_RADIUS_M",
    "SECONDS_PER_DAY",
]
