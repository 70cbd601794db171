"""Scenario fields of the lunar-return skip entry (seed 003 Tables 1-2).

File units follow the paper (km, km/s, deg, %, 3-sigma dispersions); the simulation is SI.
"""

from ...guidance.entry.reach import FPA_RANGE_DEG
from ...schema import Field, ScenarioError

F = Field

SCHEMA = {
    "entry": {
        "altitude_km": F(
            "float",
            120.0,
            lo=100.0,
            hi=200.0,
            units="km",
            doc="entry interface; below 100 km the hold phase has no air-free start, above "
            "200 km the 1800 s horizon of the reference design is spent coasting",
        ),
        "speed_kmps": F(
            "float",
            11.0,
            lo=8.0,
            hi=16.0,
            units="km/s",
            doc="Earth-relative entry speed; the design anchors the switch point at 7.3 km/s, so "
            "a skip needs more; which speeds reach the target is checked before the design",
        ),
        "fpa_deg": F(
            "float",
            -5.9,
            lo=FPA_RANGE_DEG[0],
            hi=FPA_RANGE_DEG[1],
            units="deg",
            doc="Earth-relative; steeper than -12 deg the load pulse lasts under three 2 s "
            "steps of the design and a 'pull-up' happens only near the ground, which the phase "
            "logic cannot tell from a skip; shallower than -2 deg nothing is captured; the "
            "corridor of this speed and vehicle is checked before the design",
        ),
        "azimuth_deg": F(
            "float", 34.3, lo=-360.0, hi=360.0, units="deg", doc="heading, clockwise from north"
        ),
        "longitude_deg": F("float", 63.54, lo=-360.0, hi=360.0, units="deg"),
        "latitude_deg": F("float", -3.34, lo=-90.0, hi=90.0, units="deg", doc="geocentric"),
        "range_km": F(
            "float",
            8000.0,
            lo=500.0,
            hi=15000.0,
            units="km",
            doc="great-circle range from the entry point to the target, short of the antipode "
            "(20015 km) where the along-track error is undefined; the range this entry and "
            "vehicle can reach is checked before the design",
        ),
        "chute_altitude_km": F("float", 10.0, lo=1.0, hi=40.0, units="km"),
    },
    "vehicle": {
        "mass_kg": F("float", 9000.0, lo=0.0, lo_open=True, hi=1e6, units="kg"),
        "area_m2": F("float", 22.0, lo=0.0, lo_open=True, hi=1e3, units="m^2"),
        "cl": F("float", 0.39, lo=0.0, lo_open=True, hi=5.0, doc="trim lift coefficient"),
        "cd": F("float", 1.3, lo=0.0, lo_open=True, hi=5.0, doc="trim drag coefficient"),
        "nose_radius_m": F("float", 6.35, lo=0.0, lo_open=True, hi=100.0, units="m"),
    },
    "atmosphere": {
        "model": F("str", "us76", choices=("us76", "exponential")),
        "rho0_kgm3": F(
            "float",
            1.225,
            lo=0.0,
            lo_open=True,
            hi=100.0,
            units="kg/m^3",
            doc="exponential model only",
        ),
        "scale_height_km": F(
            "float", 7.2, lo=0.1, hi=100.0, units="km", doc="exponential model only"
        ),
    },
    "actuator": {
        "max_rate_dps": F("float", 20.0, lo=0.0, lo_open=True, hi=360.0, units="deg/s"),
        "max_accel_dps2": F("float", 10.0, lo=0.0, lo_open=True, hi=3600.0, units="deg/s^2"),
        "reversal": F(
            "str",
            "shortest",
            choices=("shortest", "lift_down_pairs", "through_lift_up"),
            doc="way round of a bank reversal: 'shortest' rolls to a lift-down bank (beyond "
            "90 deg) the shorter way round, never through lift-up, and to a lift-up bank "
            "through lift-up; 'lift_down_pairs' rolls through lift-down only between two "
            "lift-down banks (a roll under way keeping its way); 'through_lift_up' rolls every "
            "reversal through lift-up (see gnc_jax.dynamics.entry.BankActuator)",
        ),
    },
    "guidance": {
        "hold_bank_deg": F(
            "float",
            60.0,
            lo=0.0,
            hi=180.0,
            units="deg",
            doc="the de-orbit attitude at the entry interface; the skip_entry law holds it "
            "until the sensed load reaches ng0_g only with guidance.skip_entry.hold_bank = "
            "'scenario' (its default, 'designed', rolls to the designed first-entry bank and "
            "holds that)",
        ),
        "pc_period_s": F(
            "float",
            4.0,
            lo=0.0,
            lo_open=True,
            hi=120.0,
            units="s",
            doc="predictor-corrector cycle; a multiple of simulation.control_dt_s",
        ),
        "ratio_filter_gain": F(
            "float", 0.2, lo=0.0, hi=1.0, doc="fading-memory gain of the drag/lift ratio estimates"
        ),
    },
    "reference": {
        "v_end_mps": F(
            "float",
            1000.0,
            lo=100.0,
            hi=7000.0,
            units="m/s",
            doc="end speed of the linear second-entry bank profile",
        ),
        "w_margin": F(
            "float",
            3.0,
            lo=0.0,
            hi=1e3,
            doc="weight of the control-margin term of the design objective",
        ),
        "design_steps": F("int", 20, lo=1, hi=1000, doc="optax Adam steps of the design"),
    },
    "simulation": {
        "dt_s": F("float", 0.5, lo=0.01, hi=10.0, units="s", doc="truth RK4 step"),
        "control_dt_s": F(
            "float", 1.0, lo=0.01, hi=10.0, units="s", doc="guidance step; a multiple of dt_s"
        ),
        "max_time_s": F("float", 2400.0, lo=10.0, hi=1e5, units="s"),
        "miss_limit_km": F(
            "float",
            100.0,
            lo=0.0,
            lo_open=True,
            hi=1000.0,
            units="km",
            doc="a run whose chute point misses the target by more (downrange or crossrange) "
            "lost the target: status out_of_domain, left out of the statistics (the paper's "
            "requirement is 2.5 km)",
        ),
    },
}


def _multiple(a, b):
    r = a / b
    return abs(r - round(r)) < 1e-9 and round(r) >= 1


def check(cfg: dict) -> None:
    """Cross-field checks of a validated capsule configuration."""
    g, s = cfg["guidance"], cfg["simulation"]
    if not _multiple(s["control_dt_s"], s["dt_s"]):
        raise ScenarioError(
            f"simulation.control_dt_s: {s['control_dt_s']:g} s; allowed: a whole multiple of "
            f"simulation.dt_s = {s['dt_s']:g} s"
        )
    if not _multiple(g["pc_period_s"], s["control_dt_s"]):
        raise ScenarioError(
            f"guidance.pc_period_s: {g['pc_period_s']:g} s; allowed: a whole multiple of "
            f"simulation.control_dt_s = {s['control_dt_s']:g} s"
        )
