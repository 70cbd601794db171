"""Epoch conversions against ERFA's calendar routines (pyerfa)."""

import re

import erfa
import numpy as np
import pytest

from gnc_jax import time as gtime

_EPOCHS = [
    (2000, 1, 1, 12, 0, 0.0),
    (2007, 9, 1, 0, 0, 0.0),
    (2008, 4, 26, 0, 0, 0.0),
    (2007, 9, 1, 12, 30, 0.0),
    (1999, 12, 31, 23, 59, 59.5),
    (2000, 2, 29, 6, 0, 0.25),
    (1900, 3, 1, 0, 0, 0.0),
    (2100, 2, 28, 18, 45, 12.125),
    (1582, 10, 4, 0, 0, 0.0),  # proleptic Gregorian: no Julian-calendar switch
    (1, 1, 1, 0, 0, 0.0),
    (9999, 12, 31, 23, 59, 59.0),
]


def _iso(y, mo, d, h, mi, s) -> str:
    return f"{y:04d}-{mo:02d}-{d:02d}T{h:02d}:{mi:02d}:{s:06.3f}"


@pytest.mark.parametrize("fields", _EPOCHS)
def test_parse_epoch_matches_erfa_dtf2d(fields):
    d1, d2 = erfa.dtf2d("TDB", *fields)
    expected = ((d1 - 2451545.0) + d2) * 86400.0
    got = gtime.parse_epoch(_iso(*fields))
    assert isinstance(got, float)
    # dtf2d returns a day fraction: its own resolution is ~1e-11 day ~ 1 microsecond.
    assert got == pytest.approx(expected, abs=2e-6)


def test_parse_epoch_date_only_matches_erfa_cal2jd():
    rng = np.random.default_rng(7)
    days = rng.integers(-400 * 366, 400 * 366, size=200)
    for day_offset in days:
        iy, im, iday, _ = erfa.jd2cal(2451544.5, float(day_offset))
        djm0, djm = erfa.cal2jd(iy, im, iday)
        text = f"{int(iy):04d}-{int(im):02d}-{int(iday):02d}"
        expected = ((djm0 - 2451545.0) + djm) * 86400.0
        assert gtime.parse_epoch(text) == expected


def test_parse_epoch_forms_and_j2000():
    assert gtime.parse_epoch("2000-01-01T12:00:00") == 0.0
    assert gtime.parse_epoch("2000-01-01") == -43200.0
    assert gtime.parse_epoch("2007-09-01T12:30") == gtime.parse_epoch("2007-09-01 12:30:00.000")
    # Phoenix cruise of seed 001: 2007-09-01 to 2008-04-26 is 238 days.
    span = gtime.parse_epoch("2008-04-26") - gtime.parse_epoch("2007-09-01")
    assert span == 238 * 86400.0


@pytest.mark.parametrize(
    "bad",
    [
        "2007-13-01",
        "2007-02-29",
        "2007-09-31",
        "2007-09-01T24:00",
        "2007-09-01T12:60",
        "2007-09-01T12:00:60",
        "07-09-01",
        "2007/09/01",
        "2007-09-01T12:00:00Z",
        "",
        "yesterday",
    ],
)
def test_parse_epoch_rejects_bad_strings_naming_them(bad):
    with pytest.raises(ValueError, match=re.escape(repr(bad))):
        gtime.parse_epoch(bad)


def test_epoch_to_iso_matches_erfa_d2dtf_and_round_trips():
    rng = np.random.default_rng(11)
    seconds = rng.uniform(-3.2e9, 3.2e9, size=300)  # about 1900..2100
    for t in seconds:
        iy, im, iday, ihmsf = erfa.d2dtf("TDB", 3, 2451545.0, t / 86400.0)
        h, m, s, f = (int(v) for v in ihmsf)
        expected = f"{int(iy):04d}-{int(im):02d}-{int(iday):02d}T{h:02d}:{m:02d}:{s:02d}.{f:03d}"
        text = gtime.epoch_to_iso(t)
        # Both round to the millisecond; a tie can fall either way, so allow one tick.
        assert abs(gtime.parse_epoch(text) - gtime.parse_epoch(expected)) <= 1e-3 + 1e-9
        assert abs(gtime.parse_epoch(text) - t) <= 5e-4 + 1e-6


def test_epoch_to_iso_carries_rounding_into_the_next_day():
    t = gtime.parse_epoch("2007-12-31T23:59:59.9996")
    assert gtime.epoch_to_iso(t) == "2008-01-01T00:00:00.000"
    assert gtime.epoch_to_iso(t, decimals=0) == "2008-01-01T00:00:00"


def test_julian_date_helpers_match_erfa():
    t = gtime.parse_epoch("2007-09-01T06:00:00")
    d1, d2 = erfa.dtf2d("TDB", 2007, 9, 1, 6, 0, 0.0)
    assert gtime.julian_date(t) == pytest.approx(d1 + d2, abs=1e-9)
    jd1, jd2 = gtime.julian_date_two_part(t)
    assert (jd1 - d1) + (jd2 - d2) == pytest.approx(0.0, abs=1e-12)
    assert gtime.seconds_from_julian_date(d1, d2) == pytest.approx(t, abs=1e-5)
    djm0, djm = erfa.cal2jd(2007, 9, 1)
    assert gtime.modified_julian_date(t) == pytest.approx(djm + 0.25, abs=1e-10)
    assert gtime.julian_centuries(t) == pytest.approx((d1 - 2451545.0 + d2) / 36525.0, rel=1e-12)
