"""Cross-field checks of the autonomous midcourse correction (seed 001).

The scenario fields are declared once in :mod:`gnc_jax.systems.midcourse.params`; these
checks read the validated configuration in its file units (epochs as TDB calendar strings,
days, km).
"""

import math

from ... import time as gtime
from ...constants import SECONDS_PER_DAY
from ...schema import ScenarioError


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
    # every fix, the first included, is more than a day before the encounter
    latest = t["encounter_epoch"] - SECONDS_PER_DAY
    if not t["launch_epoch"] < t["first_fix_epoch"] < latest:
        raise ScenarioError(
            f"mission.first_fix_epoch: {m['first_fix_epoch']!r}; allowed: after "
            f"launch_epoch ({m['launch_epoch']}) and more than 1 day before encounter_epoch "
            f"({m['encounter_epoch']})"
        )
    last = fix_epochs_s(cfg)[-1]
    if not last < latest:
        days = (latest - t["first_fix_epoch"]) / SECONDS_PER_DAY
        nav = cfg["navigation"]
        fixes = f"{nav['fixes']} fix{'' if nav['fixes'] == 1 else 'es'}"
        raise ScenarioError(
            f"navigation.fixes: {fixes} every {nav['interval_days']:g} days end "
            f"{(last - t['encounter_epoch']) / SECONDS_PER_DAY:+.1f} days from encounter; "
            "allowed: the last fix more than 1 day before encounter, i.e. "
            f"(fixes - 1) * interval_days < {days:g}"
        )
    if math.hypot(*m["aim_b_km"]) == 0.0:
        raise ScenarioError(
            "mission.aim_b_km: (0, 0) aims at the planet's centre (rectilinear, no B-plane); "
            "allowed: a non-zero (B_T, B_R)"
        )
