"""Epochs: calendar strings, seconds past J2000 TDB and Julian dates.

Every epoch inside gnc_jax is a number of SI seconds past J2000.0, 2000-01-01T12:00:00 TDB
(JD 2451545.0 TDB). TDB is a uniform time scale without leap seconds, so a calendar date in TDB
maps to seconds by the proleptic Gregorian calendar and 86400-second days alone; no UTC/leap-second
table is involved (a scenario quoting a UTC date is off by TT - UTC ~ 65 s, well below the
accuracy of the analytical ephemerides, but a caller who cares must convert first).

The string helpers (`parse_epoch`, `epoch_to_iso`) are plain Python for scenario files and
reports. The Julian-date helpers are plain arithmetic and therefore work unchanged on Python
floats, NumPy arrays and traced JAX arrays.
"""

import math
import re

from .constants import SECONDS_PER_DAY

J2000_JD = 2451545.0
"""Julian date of the J2000.0 epoch, 2000-01-01T12:00:00 TDB."""

MJD_ZERO_JD = 2400000.5
"""Julian date of MJD 0 (1858-11-17T00:00:00)."""

DAYS_PER_JULIAN_CENTURY = 36525.0

# Days from 0000-03-01 (proleptic Gregorian) to 2000-01-01, see `_days_from_civil`.
_DAYS_0000_03_01_TO_2000_01_01 = 730425
_SECONDS_NOON = 43200

_EPOCH_PATTERN = re.compile(
    r"^(?P<year>\d{4})-(?P<month>\d{2})-(?P<day>\d{2})"
    r"(?:[T ](?P<hour>\d{2}):(?P<minute>\d{2})(?::(?P<second>\d{2}(?:\.\d+)?))?)?$"
)


def _days_from_civil(year: int, month: int, day: int) -> int:
    """Days from 2000-01-01 to a proleptic Gregorian date (integer arithmetic, exact).

    The year is shifted to start on 1 March so that the leap day is the last day of the shifted
    year; 400-year eras then hold exactly 146097 days (Richards, "Mapping time", in
    Explanatory Supplement to the Astronomical Almanac, 3rd ed. 2013, ch. 15.11).
    """
    y = year - (month <= 2)
    era = y // 400
    year_of_era = y - 400 * era
    shifted_month = (month + 9) % 12  # March = 0 ... February = 11
    day_of_year = (153 * shifted_month + 2) // 5 + day - 1
    day_of_era = 365 * year_of_era + year_of_era // 4 - year_of_era // 100 + day_of_year
    return 146097 * era + day_of_era - _DAYS_0000_03_01_TO_2000_01_01


def _civil_from_days(days: int) -> tuple[int, int, int]:
    """Inverse of `_days_from_civil`: (year, month, day) of the day ``days`` after 2000-01-01."""
    z = days + _DAYS_0000_03_01_TO_2000_01_01
    era = z // 146097
    day_of_era = z - 146097 * era
    year_of_era = (
        day_of_era - day_of_era // 1460 + day_of_era // 36524 - day_of_era // 146096
    ) // 365
    day_of_year = day_of_era - (365 * year_of_era + year_of_era // 4 - year_of_era // 100)
    shifted_month = (5 * day_of_year + 2) // 153
    day = day_of_year - (153 * shifted_month + 2) // 5 + 1
    month = shifted_month + 3 if shifted_month < 10 else shifted_month - 9
    year = 400 * era + year_of_era + (month <= 2)
    return year, month, day


def _days_in_month(year: int, month: int) -> int:
    if month == 2:
        leap = year % 4 == 0 and (year % 100 != 0 or year % 400 == 0)
        return 29 if leap else 28
    return 30 if month in (4, 6, 9, 11) else 31


def calendar_to_seconds(
    year: int, month: int, day: int, hour: int = 0, minute: int = 0, second: float = 0.0
) -> float:
    """Seconds past J2000 TDB of a proleptic Gregorian TDB calendar date and time of day.

    Fields are checked (month 1-12, day within the month, hour 0-23, minute 0-59,
    0 <= second < 60: TDB has no leap seconds); a bad field raises ``ValueError``.
    """
    if not 1 <= month <= 12:
        raise ValueError(f"month {month} is not in 1..12")
    if not 1 <= day <= _days_in_month(year, month):
        raise ValueError(f"day {day} is not in month {year:04d}-{month:02d}")
    if not (0 <= hour <= 23 and 0 <= minute <= 59 and 0.0 <= second < 60.0):
        raise ValueError(f"time of day {hour:02d}:{minute:02d}:{second} is out of range")
    whole_seconds = (
        _days_from_civil(year, month, day) * 86400 + hour * 3600 + minute * 60 - _SECONDS_NOON
    )
    return float(whole_seconds) + float(second)


def parse_epoch(text: str) -> float:
    """Seconds past J2000 TDB of an ISO-8601 calendar epoch given in TDB.

    Accepted forms: ``"YYYY-MM-DD"`` (midnight), ``"YYYY-MM-DDTHH:MM"``,
    ``"YYYY-MM-DDTHH:MM:SS"`` and ``"YYYY-MM-DDTHH:MM:SS.fff"`` (a space may replace the ``T``).
    The calendar is proleptic Gregorian; no time-zone suffix is accepted because the scale is
    TDB by definition. ``parse_epoch("2000-01-01T12:00:00") == 0.0``.

    Returns a plain Python float; raises ``ValueError`` naming the string if it is malformed or
    names a date or time that does not exist.
    """
    match = _EPOCH_PATTERN.match(text.strip()) if isinstance(text, str) else None
    if match is None:
        raise ValueError(f"epoch {text!r} is not of the form YYYY-MM-DD[THH:MM[:SS[.fff]]] (TDB)")
    fields = match.groupdict()
    try:
        return calendar_to_seconds(
            int(fields["year"]),
            int(fields["month"]),
            int(fields["day"]),
            int(fields["hour"] or 0),
            int(fields["minute"] or 0),
            float(fields["second"] or 0.0),
        )
    except ValueError as error:
        raise ValueError(f"epoch {text!r} is not a valid TDB calendar date: {error}") from None


def epoch_to_iso(t_tdb_s: float, decimals: int = 3) -> str:
    """ISO-8601 TDB calendar string ``"YYYY-MM-DDTHH:MM:SS[.fff]"`` of seconds past J2000 TDB.

    ``decimals`` is the number of digits of the seconds field (0 to 9); the value is rounded to
    that resolution before it is split into date and time, so 59.9996 s never prints as 60.000.
    Inverse of `parse_epoch` to within the rounding.
    """
    if not 0 <= decimals <= 9:
        raise ValueError(f"decimals must be in 0..9, got {decimals}")
    t = float(t_tdb_s)
    if not math.isfinite(t):
        raise ValueError(f"epoch {t_tdb_s!r} is not a finite number of seconds")
    scale = 10**decimals
    # Work in integer ticks of 10**-decimals s counted from 2000-01-01T00:00:00 so the carry from
    # seconds to minutes to days is exact.
    ticks = round((t + _SECONDS_NOON) * scale)
    days, ticks_of_day = divmod(ticks, 86400 * scale)
    year, month, day = _civil_from_days(days)
    whole_seconds, fraction = divmod(ticks_of_day, scale)
    hour, rest = divmod(whole_seconds, 3600)
    minute, second = divmod(rest, 60)
    text = f"{year:04d}-{month:02d}-{day:02d}T{hour:02d}:{minute:02d}:{second:02d}"
    if decimals:
        text += f".{fraction:0{decimals}d}"
    return text


def julian_date(t_tdb_s):
    """Julian date (TDB) of seconds past J2000 TDB: JD = 2451545.0 + t / 86400.

    A single float loses ~20 microseconds of resolution near JD 2.45e6; use
    `julian_date_two_part` where that matters (ERFA/SOFA calling convention).
    """
    return J2000_JD + t_tdb_s / SECONDS_PER_DAY


def julian_date_two_part(t_tdb_s):
    """Two-part Julian date (TDB) ``(2451545.0, t / 86400)`` with full resolution.

    This is the "J2000 method" of splitting a date in ERFA/SOFA (e.g. ``erfa.plan94(*jd, np)``).
    """
    return J2000_JD, t_tdb_s / SECONDS_PER_DAY


def seconds_from_julian_date(jd1, jd2=0.0):
    """Seconds past J2000 TDB of a (two-part) Julian date in TDB.

    t = ((jd1 - 2451545.0) + jd2) * 86400 s; splitting the date keeps its full resolution.
    """
    return ((jd1 - J2000_JD) + jd2) * SECONDS_PER_DAY


def modified_julian_date(t_tdb_s):
    """Modified Julian date (TDB): MJD = JD - 2400000.5 = 51544.5 + t / 86400."""
    return (J2000_JD - MJD_ZERO_JD) + t_tdb_s / SECONDS_PER_DAY


def julian_centuries(t_tdb_s):
    """Julian centuries of 36525 days past J2000 TDB (the argument of IAU precession series)."""
    return t_tdb_s / (SECONDS_PER_DAY * DAYS_PER_JULIAN_CENTURY)
