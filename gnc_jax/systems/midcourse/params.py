"""Scenario parameters of the autonomous midcourse correction (seed 001), each declared once
with :func:`gnc_jax.params.param`.

File units follow the paper (km, m/s, days, %, deg; epochs as TDB calendar strings) and the
file names carry them; the Modules hold the SI values the simulation uses (:func:`parameters`;
epochs in seconds past J2000 TDB). Vectors are in the heliocentric EME2000 axes (the paper's
"x axis" is EME2000 x). The scenario sections, ``gnc-jax list --fields`` and the docs reference
derive from these declarations (:attr:`MidcourseSystem.parameter_modules`); the cross-field
checks are in :mod:`gnc_jax.systems.midcourse.schema`.
"""

import functools
import math
from typing import NamedTuple

import equinox as eqx
import numpy as np

from ... import time as gtime
from ..._types import Array, Float, Scalar, Vector3
from ...constants import SECONDS_PER_DAY
from ...params import from_scenario, param

# One declaration helper per section: every field of a section Module lives in that table.
_mission = functools.partial(param, section="mission")
_spacecraft = functools.partial(param, section="spacecraft")
_dynamics = functools.partial(param, section="dynamics")
_navigation = functools.partial(param, section="navigation")
_guidance = functools.partial(param, section="guidance")
_goal = functools.partial(param, section="goal")


def _pct(x):
    return x / 100.0


class Mission(eqx.Module):
    """``[mission]``: the epochs (static, s past J2000 TDB: they place the ephemeris table
    and the nominal design), the aim point and the B-plane reference."""

    launch_epoch_s: float = _mission(
        "2007-08-04",
        toml="launch_epoch",
        convert=gtime.parse_epoch,
        units="TDB",
        doc="Earth departure of the nominal Lambert transfer (Phoenix's launch date)",
    )
    encounter_epoch_s: float = _mission(
        "2008-04-26",
        toml="encounter_epoch",
        convert=gtime.parse_epoch,
        units="TDB",
        doc="nominal Mars periapsis epoch (the paper's end date: 2007-09-01 is E-238 d)",
    )
    first_fix_epoch_s: float = _mission(
        "2007-09-01",
        toml="first_fix_epoch",
        convert=gtime.parse_epoch,
        units="TDB",
        doc="first navigation fix and correction opportunity (the paper's E-238 d)",
    )
    aim_b_m: Float[Array, "2"] = _mission(
        [4200.0, -4200.0],
        toml="aim_b_km",
        scale=1e3,
        length=2,
        lo=-1e6,
        hi=1e6,
        units="km",
        doc="aim point (B_T, B_R) at Mars; |B| = 5940 km puts periapsis at 3525 km",
    )
    reference_plane: str = _mission(
        "ecliptic",
        choices=("ecliptic", "equator", "mars_orbit"),
        doc="B-plane reference plane: T = S x n with n its normal (J2000 ecliptic pole, "
        "EME2000 pole or Mars's orbit normal at encounter)",
    )


class Spacecraft(eqx.Module):
    """``[spacecraft]``: mass and the cannonball radiation-pressure model."""

    mass_kg: Scalar = _spacecraft(664.0, lo=0.0, lo_open=True, hi=1e5, units="kg")
    srp_area_m2: Scalar = _spacecraft(
        7.0, lo=0.0, hi=1e4, units="m^2", doc="cannonball cross-section for SRP"
    )
    reflectivity: Scalar = _spacecraft(
        1.3, lo=0.0, hi=2.0, doc="radiation-pressure coefficient C_r (1: absorbing)"
    )


class Dynamics(eqx.Module):
    """``[dynamics]``: force model, integrator and the closest-approach window (static: it
    sizes the ephemeris table)."""

    solver: str = _dynamics(
        "dopri8",
        choices=("dopri8", "dopri5", "tsit5"),
        doc="adaptive Runge-Kutta pair (the paper: dopri5, a 4(5) pair)",
    )
    rtol: Scalar = _dynamics(1e-13, lo=1e-15, hi=1e-6, doc="relative integration tolerance")
    atol: Scalar = _dynamics(
        1e-7, lo=0.0, lo_open=True, hi=1e3, units="m, m/s", doc="absolute tolerance"
    )
    max_steps: int = _dynamics(4096, lo=16, hi=1_000_000, doc="integrator step budget per arc")
    planets: Scalar = _dynamics(True, doc="the 8 planets as point-mass perturbations")
    ephemeris: str = _dynamics(
        "table",
        choices=("table", "plan94"),
        doc="planet positions: quintic Hermite table of plan94 at 1-day nodes (error < 1 m) "
        "or plan94 evaluated at every integrator stage (~5x slower)",
    )
    srp: Scalar = _dynamics(True, doc="solar radiation pressure (cannonball)")
    window_s: float = _dynamics(
        30.0,
        toml="window_days",
        scale=SECONDS_PER_DAY,
        static=True,
        lo=0.0,
        lo_open=True,
        hi=1000.0,
        units="days",
        doc="search for the closest approach up to this long after the nominal encounter",
    )


class Navigation(eqx.Module):
    """``[navigation]``: the fixes (the navigation errors are :class:`MidcourseErrors`)."""

    fixes: int = _navigation(
        1,
        lo=1,
        hi=1000,
        doc="navigation fixes (correction opportunities), the first at first_fix_epoch",
    )
    fix_interval_s: Scalar = _navigation(
        7.0,
        toml="interval_days",
        scale=SECONDS_PER_DAY,
        lo=0.0,
        lo_open=True,
        hi=1000.0,
        units="days",
        doc="fix interval",
    )


class Guidance(eqx.Module):
    """``[guidance]`` (the system's; the law's own table is ``[guidance.<law>]``)."""

    enabled: Scalar = _guidance(True, doc="false: no correction (the paper's Table 1 dispersion)")
    targets: str = _guidance(
        "b_plane_tof",
        choices=("b_plane_tof", "b_plane"),
        doc="Q = (B_R, B_T, t_TOF) (fixed arrival, n = m = 3) or (B_R, B_T) (free arrival, "
        "minimum-norm Δv)",
    )


class Goal(eqx.Module):
    """``[goal]``: the success goal of the statistics."""

    b_m: Scalar = _goal(
        10.0,
        toml="b_km",
        scale=1e3,
        lo=0.0,
        lo_open=True,
        hi=1e7,
        units="km",
        doc="goal on |dB| (paper)",
    )
    tof_s: Scalar = _goal(60.0, lo=0.0, lo_open=True, hi=1e8, units="s", doc="goal on |dt| (paper)")


class MidcourseErrors(eqx.Module):
    """Error sources (SI, EME2000 axes). Initial errors are drawn once per run; navigation and
    execution errors at every fix. Each field is declared once with its scenario field
    (``[dispersion]``, ``[navigation]``, ``[execution]``), from which those sections derive.
    """

    position_m: Scalar = param(
        289.0,
        toml="position_km",
        section="dispersion",
        scale=1e3,
        lo=0.0,
        hi=1e6,
        units="km",
        doc="1-sigma initial position, per axis",
    )
    velocity_mps: Scalar = param(
        0.577,
        section="dispersion",
        lo=0.0,
        hi=1e3,
        units="m/s",
        doc="1-sigma initial velocity, per axis",
    )
    position_offset_m: Vector3 = param(
        [0.0, 0.0, 0.0],
        toml="position_offset_km",
        section="dispersion",
        scale=1e3,
        length=3,
        lo=-1e6,
        hi=1e6,
        units="km",
        doc="deterministic initial position error (the paper's cycle cases: 500 km in x)",
    )
    velocity_offset_mps: Vector3 = param(
        [0.0, 0.0, 0.0],
        section="dispersion",
        length=3,
        lo=-1e3,
        hi=1e3,
        units="m/s",
        doc="deterministic initial velocity error (the paper's cycle cases: 1 m/s in x)",
    )
    nav_position_m: Scalar = param(
        0.0,
        toml="position_sigma_km",
        section="navigation",
        scale=1e3,
        lo=0.0,
        hi=1e6,
        units="km",
        doc="1-sigma random position error per fix",
    )
    nav_velocity_mps: Scalar = param(
        0.0,
        toml="velocity_sigma_mps",
        section="navigation",
        lo=0.0,
        hi=1e3,
        units="m/s",
        doc="1-sigma random velocity error per fix",
    )
    nav_position_bias_m: Vector3 = param(
        [0.0, 0.0, 0.0],
        toml="position_bias_km",
        section="navigation",
        scale=1e3,
        length=3,
        lo=-1e6,
        hi=1e6,
        units="km",
        doc="constant position error of every fix",
    )
    nav_velocity_bias_mps: Vector3 = param(
        [0.0, 0.0, 0.0],
        toml="velocity_bias_mps",
        section="navigation",
        length=3,
        lo=-1e3,
        hi=1e3,
        units="m/s",
        doc="constant velocity error of every fix (the paper: 0.3 m/s in x)",
    )
    final_fix_scale: Scalar = param(
        1.0,
        section="navigation",
        lo=0.0,
        hi=1e3,
        doc="the last fix's error is scaled by this (the paper's 0.01 m/s final fix: 1/30)",
    )
    magnitude_bias: Scalar = param(
        0.0,
        toml="magnitude_bias_pct",
        section="execution",
        convert=_pct,
        lo=-50.0,
        hi=50.0,
        units="%",
        doc="systematic burn magnitude error (the paper: 3 % and 5 %)",
    )
    magnitude_sigma: Scalar = param(
        0.0,
        toml="magnitude_sigma_pct",
        section="execution",
        convert=_pct,
        lo=0.0,
        hi=50.0,
        units="%",
        doc="1-sigma random magnitude error",
    )
    pointing_sigma_rad: Scalar = param(
        0.0,
        toml="pointing_sigma_deg",
        section="execution",
        convert=math.radians,
        lo=0.0,
        hi=30.0,
        units="deg",
        doc="1-sigma pointing error per axis",
    )

    def has_per_fix_errors(self) -> bool:
        """Whether navigation or execution errors are on (then the Δv baseline of
        ``dv_increase_pct`` is solved apart, from the true initial state)."""
        return any(
            bool(np.any(np.asarray(v) != 0.0))
            for v in (
                self.nav_position_m,
                self.nav_velocity_mps,
                self.nav_position_bias_m,
                self.nav_velocity_bias_mps,
                self.magnitude_bias,
                self.magnitude_sigma,
                self.pointing_sigma_rad,
            )
        )


class MidcourseParameters(NamedTuple):
    """Every scenario parameter of a midcourse scenario, SI (:func:`parameters`)."""

    mission: Mission
    spacecraft: Spacecraft
    dynamics: Dynamics
    navigation: Navigation
    guidance: Guidance
    goal: Goal
    errors: MidcourseErrors


PARAMETER_MODULES = (Mission, Spacecraft, Dynamics, Navigation, Guidance, Goal, MidcourseErrors)
"""The Modules that declare the midcourse scenario fields, in the order of its sections."""


def parameters(config: dict) -> MidcourseParameters:
    """The SI parameters of a validated midcourse configuration."""
    return MidcourseParameters(*(from_scenario(cls, config) for cls in PARAMETER_MODULES))


__all__ = [
    "Mission",
    "Spacecraft",
    "Dynamics",
    "Navigation",
    "Guidance",
    "Goal",
    "MidcourseErrors",
    "MidcourseParameters",
    "PARAMETER_MODULES",
    "parameters",
]
