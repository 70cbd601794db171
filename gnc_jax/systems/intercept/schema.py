"""Scenario fields of the variable-coefficient augmented PN intercept (seed 004).

File units follow the paper (km, km/s, AU, deg, urad) and are converted to SI when the
simulation is built; the field names carry the units. Where the paper is silent (engine,
guidance step, pulse width, trigger thresholds, navigation sensor rate) the defaults and their
reasons are given in the field docs and in README "Augmented PN".
"""

import math

from ...constants import AU_M
from ...schema import Field, ScenarioError

F = Field

SUN_RADIUS_M = 6.957e8  # IAU 2015 nominal solar radius

SCHEMA = {
    "approach": {
        "geometry": F(
            "str",
            "planar",
            choices=("planar", "bennu-3d"),
            doc="planar: seed 004 Table 2 states as given (z = 0); bennu-3d: the target from "
            "the Table 1 elements and the Table 2 relative state rotated into its (radial, "
            "transverse, normal) frame",
        ),
        "target_position_km": F(
            "floats", [1.34175e8, 0.0, 0.0], length=3, units="km", doc="Table 2 (planar)"
        ),
        "target_velocity_kmps": F(
            "floats", [0.0, 34.50561, 0.0], length=3, units="km/s", doc="Table 2 (planar)"
        ),
        "impactor_position_km": F(
            "floats", [1.34176e8, 9.36358e5, 0.0], length=3, units="km", doc="Table 2"
        ),
        "impactor_velocity_kmps": F(
            "floats", [0.0, 24.30561, 0.0], length=3, units="km/s", doc="Table 2"
        ),
        "semi_major_axis_au": F("float", 1.12639, lo=0.0, lo_open=True, hi=100.0, units="AU"),
        "eccentricity": F("float", 0.20375, lo=0.0, hi=0.99),
        "inclination_deg": F("float", 6.03494, lo=0.0, hi=180.0, units="deg"),
        "raan_deg": F("float", 2.06087, lo=-360.0, hi=360.0, units="deg"),
        "arg_perihelion_deg": F("float", 66.22307, lo=-360.0, hi=360.0, units="deg"),
        "true_anomaly_deg": F("float", 101.70395, lo=-360.0, hi=360.0, units="deg"),
    },
    "dynamics": {
        "mu_sun_m3s2": F("float", 1.32715e20, lo=0.0, lo_open=True, hi=1e22, units="m^3/s^2"),
        "mu_target_m3s2": F(
            "float",
            4.892,
            lo=0.0,
            hi=1e12,
            units="m^3/s^2",
            doc="Bennu GM (Scheeres et al. 2019); 0 = no target gravity",
        ),
        "target_radius_m": F(
            "float", 245.0, lo=0.0, lo_open=True, hi=1e7, units="m", doc="homogeneous sphere"
        ),
    },
    "spacecraft": {
        "mass_kg": F("float", 372.0, lo=0.0, lo_open=True, hi=1e5, units="kg", doc="seed 000"),
        "thrust_n": F("float", 88.0, lo=0.0, lo_open=True, hi=1e4, units="N", doc="seed 000"),
        "isp_s": F(
            "float", 230.0, lo=10.0, hi=1e4, units="s", doc="specific impulse; >= 10 s: a thruster"
        ),
        "pulse_width_s": F(
            "float",
            0.05,
            lo=0.0,
            lo_open=True,
            hi=60.0,
            units="s",
            doc="engine on-time per control step while the trigger is on (minimum impulse "
            "bit = thrust x pulse width); must not exceed guidance.dt_s",
        ),
    },
    "guidance": {
        "coast_s": F(
            "float",
            600.0,
            lo=0.0,
            lo_open=True,
            units="s",
            doc="no firing in the last coast_s (paper: 10 min)",
        ),
        "dt_s": F(
            "float", 1.0, lo=0.0, lo_open=True, hi=60.0, units="s", doc="guidance/control step"
        ),
        "coast_steps": F(
            "int", 60, lo=1, hi=100000, doc="RK4 steps of the final unpowered coast to the B-plane"
        ),
    },
    "navigation": {
        "model": F(
            "str",
            "ekf",
            choices=("ekf", "perfect"),
            doc="ekf: camera LOS angles + EKF (navigation/ekf.py); perfect: the true state",
        ),
        "image_interval_s": F(
            "float",
            1.0,
            lo=0.0,
            lo_open=True,
            hi=3600.0,
            units="s",
            doc="LOS measurement interval; a whole multiple of guidance.dt_s (paper: every "
            "guidance step, Fig. 4)",
        ),
        "process_noise_m2s3": F("float", 1e-18, lo=0.0, hi=1.0, units="m^2/s^3"),
    },
}


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
