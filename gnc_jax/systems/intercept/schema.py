"""Cross-field checks of the variable-coefficient augmented PN intercept (seed 004).

The scenario fields are declared once in :mod:`gnc_jax.systems.intercept.params`; these
checks read the validated configuration in its file units (km, km/s, AU, deg).
"""

import math

from ...constants import AU_M, SECONDS_PER_DAY
from ...schema import ScenarioError

SUN_RADIUS_M = 6.957e8  # IAU 2015 nominal solar radius
MIN_RANGE_RADII = 2.0  # the approach starts at least this many target radii from its centre
# A terminal intercept (seed 004: 1.06 days): the B-plane is that of the initial relative
# velocity and the loop is sized by the straight-line time of flight; longer approaches are
# cruise (the midcourse system), as in the impactor.
MAX_TOF_S = 30 * SECONDS_PER_DAY


def _relative_state_m(cfg: dict) -> tuple[list[float], list[float]]:
    """The Table 2 impactor position (m) and velocity (m/s) relative to the target."""
    a = cfg["approach"]
    r = [1e3 * (s - t) for s, t in zip(a["impactor_position_km"], a["target_position_km"])]
    v = [1e3 * (s - t) for s, t in zip(a["impactor_velocity_kmps"], a["target_velocity_kmps"])]
    return r, v


def time_of_flight_s(cfg: dict) -> float:
    """Straight-line time of flight (s) of the Table 2 relative state."""
    r, v = _relative_state_m(cfg)
    vv = sum(x * x for x in v)
    return -sum(x * y for x, y in zip(r, v)) / vv if vv > 0 else -1.0


def check(cfg: dict) -> None:
    """Cross-field checks of a validated pn configuration."""
    a, g, sc, nv = cfg["approach"], cfg["guidance"], cfg["spacecraft"], cfg["navigation"]
    if a["geometry"] == "planar":
        for name in ("target_position_km", "impactor_position_km"):
            r = 1e3 * math.hypot(*a[name])
            if not r > SUN_RADIUS_M:
                raise ScenarioError(
                    f"approach.{name}: {a[name]} is {r:.3g} m from the Sun's centre; allowed: a "
                    f"heliocentric position above the Sun's radius, {SUN_RADIUS_M:g} m"
                )
        for name in (
            "target_position_km",
            "target_velocity_kmps",
            "impactor_position_km",
            "impactor_velocity_kmps",
        ):
            if a[name][2] != 0.0:
                raise ScenarioError(
                    f"approach.{name}: z = {a[name][2]:g} in a planar scenario; allowed: z = 0 "
                    "(or approach.geometry = 'bennu-3d')"
                )
    if a["geometry"] == "bennu-3d":
        # r = a (1 - e^2) / (1 + e cos nu) of the Table 1 elements (e <= 0.99: a positive
        # denominator); inside the Sun the target's state is meaningless, and below ~1e-150 m
        # its direction is not even computable (0/0 in simulation.pn.initial_state).
        e, nu = a["eccentricity"], math.radians(a["true_anomaly_deg"])
        r = a["semi_major_axis_au"] * AU_M * (1.0 - e * e) / (1.0 + e * math.cos(nu))
        if not r > SUN_RADIUS_M:
            raise ScenarioError(
                f"approach.semi_major_axis_au: {a['semi_major_axis_au']:g} AU (eccentricity "
                f"{e:g}, true anomaly {a['true_anomaly_deg']:g} deg) puts the target {r:.3g} m "
                f"from the Sun's centre; allowed: elements with a heliocentric distance above "
                f"the Sun's radius, {SUN_RADIUS_M:g} m"
            )
    _check_range(cfg)
    tof = time_of_flight_s(cfg)
    if tof <= 0.0:
        raise ScenarioError(
            "approach.impactor_velocity_kmps: the impactor must close on the target; allowed: "
            "a relative velocity with (relative position . relative velocity) < 0"
        )
    if not tof <= MAX_TOF_S:
        raise ScenarioError(
            f"approach.impactor_position_km: time of flight {tof / SECONDS_PER_DAY:.4g} days "
            f"(range / closing speed); allowed: at most {MAX_TOF_S / SECONDS_PER_DAY:g} days (a "
            "terminal intercept: the B-plane is fixed by the initial relative velocity; longer "
            "approaches are a midcourse problem)"
        )
    if not sc["propellant_kg"] < sc["mass_kg"]:
        raise ScenarioError(
            f"spacecraft.propellant_kg: {sc['propellant_kg']:g} kg is not less than "
            f"spacecraft.mass_kg = {sc['mass_kg']:g} kg; allowed: [0, mass_kg)"
        )
    if not g["coast_s"] < tof:
        raise ScenarioError(
            f"guidance.coast_s: {g['coast_s']:g}; allowed: (0, {tof:.6g}) s (time of flight)"
        )
    if sc["pulse_width_s"] > g["dt_s"]:
        raise ScenarioError(
            f"spacecraft.pulse_width_s: {sc['pulse_width_s']:g} > guidance.dt_s = "
            f"{g['dt_s']:g}; allowed: (0, dt_s]"
        )
    # The loop runs whole images (of whole steps) up to the first image boundary at or after
    # the cut-off: less than one interval past it, so an interval within the final coast ends
    # the loop before the B-plane (a longer one can fly the truth past it).
    if not g["dt_s"] <= g["coast_s"]:
        raise ScenarioError(
            f"guidance.dt_s: {g['dt_s']:g} s is longer than guidance.coast_s = "
            f"{g['coast_s']:g} s: the guidance loop, in whole steps, would end past the "
            f"B-plane; allowed: (0, {g['coast_s']:g}] s"
        )
    ratio = nv["image_interval_s"] / g["dt_s"]
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ScenarioError(
            f"navigation.image_interval_s: {nv['image_interval_s']:g} s is not a whole "
            f"multiple of guidance.dt_s = {g['dt_s']:g} s; allowed: n x dt_s, n >= 1"
        )
    if not nv["image_interval_s"] <= g["coast_s"]:
        raise ScenarioError(
            f"navigation.image_interval_s: {nv['image_interval_s']:g} s is longer than "
            f"guidance.coast_s = {g['coast_s']:g} s: the guidance loop, in whole images, would "
            f"end past the B-plane; allowed: n x {g['dt_s']:g} s (guidance.dt_s), n >= 1, up "
            f"to {g['coast_s']:g} s"
        )


def _check_range(cfg: dict) -> None:
    """The approach starts outside the target: more than ``MIN_RANGE_RADII`` radii from its
    centre."""
    r = math.hypot(*_relative_state_m(cfg)[0])
    radius = cfg["dynamics"]["target_radius_m"]
    if not r > MIN_RANGE_RADII * radius:
        raise ScenarioError(
            f"approach.impactor_position_km: {r:.4g} m from the target's centre; allowed: more "
            f"than {MIN_RANGE_RADII:g} target radii ({MIN_RANGE_RADII * radius:g} m, "
            "dynamics.target_radius_m)"
        )
