"""Cross-field checks of the variable-coefficient augmented PN intercept (seed 004).

The scenario fields are declared once in :mod:`gnc_jax.systems.intercept.params`; these
checks read the validated configuration in its file units (km, km/s, AU, deg).
"""

import math

from ...constants import AU_M
from ...schema import ScenarioError

SUN_RADIUS_M = 6.957e8  # IAU 2015 nominal solar radius


def time_of_flight_s(cfg: dict) -> float:
    """Straight-line time of flight (s) of the Table 2 relative state."""
    a = cfg["approach"]
    r = [1e3 * (s - t) for s, t in zip(a["impactor_position_km"], a["target_position_km"])]
    v = [1e3 * (s - t) for s, t in zip(a["impactor_velocity_kmps"], a["target_velocity_kmps"])]
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
    tof = time_of_flight_s(cfg)
    if tof <= 0.0:
        raise ScenarioError(
            "approach.impactor_velocity_kmps: the impactor must close on the target; allowed: "
            "a relative velocity with (relative position . relative velocity) < 0"
        )
    if not g["coast_s"] < tof:
        raise ScenarioError(
            f"guidance.coast_s: {g['coast_s']:g}; allowed: [0, {tof:.6g}) s (time of flight)"
        )
    if sc["pulse_width_s"] > g["dt_s"]:
        raise ScenarioError(
            f"spacecraft.pulse_width_s: {sc['pulse_width_s']:g} > guidance.dt_s = "
            f"{g['dt_s']:g}; allowed: (0, dt_s]"
        )
    ratio = nv["image_interval_s"] / g["dt_s"]
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ScenarioError(
            f"navigation.image_interval_s: {nv['image_interval_s']:g} s is not a whole "
            f"multiple of guidance.dt_s = {g['dt_s']:g} s; allowed: n x dt_s, n >= 1"
        )
