"""Scenario parameters of the variable-coefficient augmented PN intercept (seed 004), each
declared once with :func:`gnc_jax.params.param`.

File units follow the paper (km, km/s, AU, deg, urad) and the file names carry them; the
Modules hold the SI values the simulation uses (:func:`parameters`). Where the paper is silent
(engine, guidance step, pulse width, trigger thresholds, navigation sensor rate) the defaults
and their reasons are given in the field docs and in docs/explanation/seed-004-apn.md. The
scenario sections, ``gnc-jax list --fields`` and the docs reference derive from these
declarations (:attr:`InterceptSystem.parameter_modules`); the cross-field checks are in
:mod:`gnc_jax.systems.intercept.schema`.
"""

import functools
from typing import NamedTuple

import equinox as eqx
import numpy as np

from ..._types import Array, Float, Scalar, Vector3
from ...constants import AU_M
from ...params import from_scenario, param
from ..impact import miss_limit_param

_DEG = np.pi / 180.0  # as the conversion was always written (not math.radians: other bits)

# One declaration helper per section: every field of a section Module lives in that table.
_approach = functools.partial(param, section="approach")
_dynamics = functools.partial(param, section="dynamics")
_spacecraft = functools.partial(param, section="spacecraft")
_guidance = functools.partial(param, section="guidance")
_navigation = functools.partial(param, section="navigation")


class Approach(eqx.Module):
    """``[approach]``: the initial heliocentric states (Table 2) or the target's elements
    (Table 1), SI."""

    geometry: str = _approach(
        "planar",
        choices=("planar", "bennu-3d"),
        doc="planar: seed 004 Table 2 states as given (z = 0); bennu-3d: the target from "
        "the Table 1 elements and the Table 2 relative state rotated into its (radial, "
        "transverse, normal) frame",
    )
    target_position_m: Vector3 = _approach(
        [1.34175e8, 0.0, 0.0],
        toml="target_position_km",
        scale=1e3,
        length=3,
        units="km",
        doc="Table 2 (planar)",
    )
    target_velocity_mps: Vector3 = _approach(
        [0.0, 34.50561, 0.0],
        toml="target_velocity_kmps",
        scale=1e3,
        length=3,
        units="km/s",
        doc="Table 2 (planar)",
    )
    impactor_position_m: Vector3 = _approach(
        [1.34176e8, 9.36358e5, 0.0],
        toml="impactor_position_km",
        scale=1e3,
        length=3,
        units="km",
        doc="Table 2",
    )
    impactor_velocity_mps: Vector3 = _approach(
        [0.0, 24.30561, 0.0],
        toml="impactor_velocity_kmps",
        scale=1e3,
        length=3,
        units="km/s",
        doc="Table 2",
    )
    semi_major_axis_m: Scalar = _approach(
        1.12639, toml="semi_major_axis_au", scale=AU_M, lo=0.0, lo_open=True, hi=100.0, units="AU"
    )
    eccentricity: Scalar = _approach(0.20375, lo=0.0, hi=0.99)
    inclination_rad: Scalar = _approach(
        6.03494, toml="inclination_deg", scale=_DEG, lo=0.0, hi=180.0, units="deg"
    )
    raan_rad: Scalar = _approach(
        2.06087, toml="raan_deg", scale=_DEG, lo=-360.0, hi=360.0, units="deg"
    )
    arg_perihelion_rad: Scalar = _approach(
        66.22307, toml="arg_perihelion_deg", scale=_DEG, lo=-360.0, hi=360.0, units="deg"
    )
    true_anomaly_rad: Scalar = _approach(
        101.70395, toml="true_anomaly_deg", scale=_DEG, lo=-360.0, hi=360.0, units="deg"
    )


class Dynamics(eqx.Module):
    """``[dynamics]``: the Sun's and the target's gravity, the target's size."""

    mu_sun_m3s2: Scalar = _dynamics(1.32715e20, lo=0.0, lo_open=True, hi=1e22, units="m^3/s^2")
    mu_target_m3s2: Scalar = _dynamics(
        4.892,
        lo=0.0,
        hi=1e12,
        units="m^3/s^2",
        doc="Bennu GM (Scheeres et al. 2019); 0 = no target gravity",
    )
    target_radius_m: Scalar = _dynamics(
        245.0, lo=0.0, lo_open=True, hi=1e7, units="m", doc="homogeneous sphere"
    )


class Spacecraft(eqx.Module):
    """``[spacecraft]``: mass and the pulsed engine."""

    mass_kg: Scalar = _spacecraft(372.0, lo=0.0, lo_open=True, hi=1e5, units="kg", doc="seed 000")
    propellant_kg: Scalar = _spacecraft(
        25.0,
        lo=0.0,
        hi=1e5,
        units="kg",
        doc="usable propellant, less than mass_kg (not in the paper: seed 000's 25 kg, 157 m/s "
        "at 230 s on 372 kg); a run that burns more is flagged 'propellant'",
    )
    thrust_n: Scalar = _spacecraft(88.0, lo=0.0, lo_open=True, hi=1e4, units="N", doc="seed 000")
    isp_s: Scalar = _spacecraft(
        230.0, lo=10.0, hi=1e4, units="s", doc="specific impulse; >= 10 s: a thruster"
    )
    pulse_width_s: Scalar = _spacecraft(
        0.05,
        lo=0.0,
        lo_open=True,
        hi=60.0,
        units="s",
        doc="engine on-time per control step while the trigger is on (minimum impulse "
        "bit = thrust x pulse width); must not exceed guidance.dt_s",
    )


class Guidance(eqx.Module):
    """``[guidance]`` (the system's; the law's gains are in ``[guidance.<law>]``). Static: the
    times size the loops (:func:`gnc_jax.systems.intercept.build.loop_sizes`). The delivery
    tolerance ``miss_limit_m`` is what a run's status is judged by."""

    coast_s: float = _guidance(
        600.0,
        lo=0.0,
        lo_open=True,
        units="s",
        static=True,
        doc="no firing in the last coast_s (paper: 10 min)",
    )
    dt_s: float = _guidance(
        1.0, lo=0.0, lo_open=True, hi=60.0, units="s", static=True, doc="guidance/control step"
    )
    coast_steps: int = _guidance(
        60, lo=1, hi=100000, doc="RK4 steps of the final unpowered coast to the B-plane"
    )
    miss_limit_m: Scalar = miss_limit_param()


class Navigation(eqx.Module):
    """``[navigation]``: the filter and its camera rate (the knowledge errors are
    :class:`PNErrors`)."""

    model: str = _navigation(
        "ekf",
        choices=("ekf", "perfect"),
        doc="ekf: camera LOS angles + EKF (navigation/ekf.py); perfect: the true state",
    )
    image_interval_s: float = _navigation(
        1.0,
        lo=0.0,
        lo_open=True,
        hi=3600.0,
        units="s",
        static=True,
        doc="LOS measurement interval; a whole multiple of guidance.dt_s, at most "
        "guidance.coast_s (paper: every guidance step, Fig. 4)",
    )
    process_noise_m2s3: Scalar = _navigation(1e-18, lo=0.0, hi=1.0, units="m^2/s^3")
    model_attitude_rad: Scalar = _navigation(
        -1.0,
        toml="model_attitude_urad",
        convert=lambda urad: urad * 1e-6,
        lo=-1.0,
        hi=1e5,
        units="urad",
        doc="1-sigma LOS angle noise the filter assumes; negative: the truth's "
        "errors.attitude_urad",
    )


class PNErrors(eqx.Module):
    """1-sigma error sources (seed 004 Table 4), SI; each field declared once with its
    scenario field (``[navigation]`` knowledge, ``[errors]``)."""

    knowledge_position_m: Float[Array, "3"] = param(
        [100.0, 10.0, 10.0],
        toml="knowledge_position_km",
        section="navigation",
        scale=1e3,
        length=3,
        lo=0.0,
        hi=1e6,
        units="km",
        doc="1-sigma initial position knowledge along the LOS, across it in the orbit "
        "plane, and out of plane (Table 4: (100, 10); planar runs ignore the third)",
    )
    knowledge_velocity_mps: Scalar = param(
        0.1, section="navigation", lo=0.0, hi=1e3, units="m/s", doc="1-sigma per axis (Table 4)"
    )
    attitude_rad: Scalar = param(
        320.0,
        toml="attitude_urad",
        section="errors",
        convert=lambda urad: urad * 1e-6,
        lo=0.0,
        hi=1e5,
        units="urad",
        doc="1-sigma attitude measurement error (Table 4): white on every LOS measurement, "
        "and the thrust pointing error of each firing",
    )


class InterceptParameters(NamedTuple):
    """Every scenario parameter of an intercept scenario, SI (:func:`parameters`)."""

    approach: Approach
    dynamics: Dynamics
    spacecraft: Spacecraft
    guidance: Guidance
    navigation: Navigation
    errors: PNErrors


PARAMETER_MODULES = (Approach, Dynamics, Spacecraft, Guidance, Navigation, PNErrors)
"""The Modules that declare the intercept's scenario fields, in the order of its sections."""


def parameters(config: dict) -> InterceptParameters:
    """The SI parameters of a validated intercept configuration."""
    return InterceptParameters(*(from_scenario(cls, config) for cls in PARAMETER_MODULES))


__all__ = [
    "Approach",
    "Dynamics",
    "Spacecraft",
    "Guidance",
    "Navigation",
    "PNErrors",
    "InterceptParameters",
    "PARAMETER_MODULES",
    "parameters",
]
