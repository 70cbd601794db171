"""Scenario parameters of the impactor terminal phase (seed 000 Table 2, seed 002), each
declared once.

Every field of an impactor scenario is a :func:`~gnc_jax.params.param` of one of the Modules
below: its default and range in the file's units (the papers' km, km/s, urad, ug, %), its
conversion to SI, its meaning and its section. The schema (``gnc-jax list --fields``, the docs
reference, validation) and the SI values that :func:`~gnc_jax.systems.impactor.build.build`
and the cost model use derive from these declarations (the error sources' Module is in
:mod:`gnc_jax.systems.impactor.errors`); :func:`timeline` derives the mission times and loop
sizes from them, in one place. The cross-field checks of a configuration are in
:mod:`gnc_jax.systems.impactor.schema`.
"""

import math
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from ..._types import Array, Float, Scalar, Vector3
from ...constants import AU_M
from ...guidance.impactor.base import mission_time_s, nominal_time_of_flight_s
from ...navigation.camera import small_rotation
from ...navigation.render import CameraModel, TargetModel
from ...params import from_scenario, param
from ..impact import miss_limit_param
from .errors import UG, URAD, ImpactorErrors
from .schema import MAX_TIDE_RATIO, MIN_RANGE_RADII, MIN_SPEED_KMPS, MIN_SUN_AU, guided_loop


class Approach(eqx.Module):
    """The nominal approach, relative to the target, inertial (SI)."""

    position_m: Float[Array, "3"] = param(
        [73440.0, 0.0, 0.0],
        toml="position_km",
        section="approach",
        scale=1e3,
        length=3,
        lo=-1e7,
        hi=1e7,
        units="km",
        doc="nominal initial position of the impactor relative to the target; |r| in "
        f"({MIN_RANGE_RADII:g} target radii, 1e7 km]: a terminal approach (the B-plane frame "
        "is fixed by the initial relative velocity, the solar tide is linearised in |r|)",
    )
    velocity_mps: Float[Array, "3"] = param(
        [-10.2, 0.0, 0.0],
        toml="velocity_kmps",
        section="approach",
        scale=1e3,
        length=3,
        lo=-100.0,
        hi=100.0,
        units="km/s",
        doc="nominal relative velocity (defines the B-plane S axis); speed in "
        f"[{MIN_SPEED_KMPS * 1e3:g} m/s, 100 km/s]: an impact, not a rendezvous",
    )
    reference_normal: Float[Array, "3"] = param(
        [0.0, 0.0, 1.0],
        section="approach",
        length=3,
        lo=-1e6,
        hi=1e6,
        doc="normal h of the B-plane reference plane (T = S x h); a direction: its length "
        "is ignored but must be in [1e-6, 1e6]",
    )


class Spacecraft(eqx.Module):
    """The impactor's mass and engine (SI)."""

    mass_kg: Scalar = param(
        372.0, section="spacecraft", lo=0.0, lo_open=True, hi=1e5, units="kg", doc="wet mass"
    )
    propellant_kg: Scalar = param(
        25.0,
        section="spacecraft",
        lo=0.0,
        hi=1e5,
        units="kg",
        doc="usable propellant, less than mass_kg (not in the paper: 25 kg, ~150 m/s at "
        "230 s on 372 kg, well above the paper's 9.1 m/s); a run that needs more is "
        "flagged 'propellant'",
    )
    thrust_n: Scalar = param(88.0, section="spacecraft", lo=0.0, lo_open=True, hi=1e4, units="N")
    isp_s: Scalar = param(
        230.0,
        section="spacecraft",
        lo=10.0,
        hi=1e4,
        units="s",
        doc="specific impulse (hydrazine monopropellant class; not in the paper); >= 10 s: "
        "a thruster",
    )


class ImpactorDynamicsParams(eqx.Module):
    """The true differential gravity and the final coast (SI). The constants are Python
    floats: whether a term is computed at all is decided by them (``RelativeDynamics.of``)."""

    mu_target_m3s2: float = param(
        0.0,
        section="dynamics",
        static=True,
        lo=0.0,
        hi=1e12,
        units="m^3/s^2",
        doc="target GM; 0 = no target gravity (paper: straight line)",
    )
    sun_distance_m: float = param(
        0.0,
        toml="sun_distance_au",
        section="dynamics",
        scale=AU_M,
        static=True,
        lo=0.0,
        hi=100.0,
        units="AU",
        doc="target's heliocentric distance for the solar tide; 0 = off, else at least "
        f"{MIN_SUN_AU:g} AU and {1 / MAX_TIDE_RATIO:g} x the approach range (the tide is "
        "linearised in range / Sun distance)",
    )
    sun_direction: Float[Array, "3"] = param(
        [1.0, 0.0, 0.0],
        section="dynamics",
        length=3,
        lo=-1e6,
        hi=1e6,
        doc="direction from the target to the Sun (solar tide; image front-end lighting); "
        "length in [1e-6, 1e6]",
    )
    coast_steps: int = param(
        4, section="dynamics", lo=1, hi=10000, doc="RK4 steps of the final coast to the B-plane"
    )

    @property
    def sun_unit(self) -> Vector3:
        """Unit vector from the target to the Sun."""
        return self.sun_direction / jnp.linalg.norm(self.sun_direction)


class CameraParams(eqx.Module):
    """The navigation camera and detector (SI), with the image cadence. The detector fields
    are those of the image front end (``navigation.measurement = "image"``); defaults of the
    Deep Impact MRI class."""

    focal_length_m: Scalar = param(
        2.103, section="camera", lo=0.0, lo_open=True, hi=100.0, units="m"
    )
    image_interval_s: float = param(
        15.0,
        section="camera",
        static=True,
        lo=0.0,
        lo_open=True,
        hi=3600.0,
        units="s",
        doc="one image every interval from t = 0; an interval that does not divide the time to "
        "the cut-off leaves a shorter last one, ending at the cut-off",
    )
    pixel_pitch_m: Scalar = param(
        21.0,
        toml="pixel_pitch_um",
        section="camera",
        scale=1e-6,
        lo=0.0,
        lo_open=True,
        hi=1e3,
        units="um",
        doc="native pixel size",
    )
    psf_sigma_px: Scalar = param(
        0.7, section="camera", lo=0.05, hi=20.0, units="px", doc="Gaussian PSF sigma, native pixels"
    )
    signal_e: Scalar = param(
        20000.0,
        section="camera",
        lo=1.0,
        hi=1e7,
        units="e-",
        doc="auto-exposure: electrons of a fully lit (cos i = 1) binned pixel",
    )
    full_well_e: Scalar = param(
        100000.0, section="camera", lo=1.0, hi=1e8, units="e-", doc="clipping level"
    )
    read_noise_e: Scalar = param(
        20.0, section="camera", lo=0.0, hi=1e5, units="e-", doc="per pixel read"
    )
    adc_bits: int = param(
        14, section="camera", lo=8, hi=24, doc="quantisation; gain = full_well/(2^bits-1)"
    )
    bias_dn: Scalar = param(
        100.0,
        section="camera",
        lo=1.0,
        hi=1e6,
        units="DN",
        doc="pedestal (the threshold is 2 x the first column's mean)",
    )
    roi_px: int = param(
        32, section="camera", lo=8, hi=512, units="px", doc="ROI side, binned pixels"
    )
    window_px: int = param(
        17,
        section="camera",
        lo=3,
        hi=511,
        units="px",
        doc="sub-pixel window side (odd), binned pixels",
    )
    samples: int = param(32, section="camera", lo=4, hi=512, doc="rays per axis over the target")
    label_iterations: int = param(
        24,
        section="camera",
        lo=1,
        hi=10000,
        doc="sweeps of the connected-component labelling",
    )
    max_bin_log2: int = param(
        7, section="camera", lo=0, hi=12, doc="largest binning is 2^max_bin_log2"
    )
    max_exposure_gain: Scalar = param(
        1e4,
        section="camera",
        lo=1.0,
        hi=1e8,
        doc="auto-exposure on the brightest pixel: longest exposure over the resolved-disc "
        "exposure (1 = the resolved-disc exposure always; point-like targets need more)",
    )

    def model(self) -> CameraModel:
        """The camera and detector model of the image front end; the ADC's largest grey
        level and gain follow from its bits."""
        adc_max = 2.0**self.adc_bits - 1.0
        return CameraModel(
            focal_length_m=self.focal_length_m,
            pixel_pitch_m=self.pixel_pitch_m,
            psf_sigma_px=self.psf_sigma_px,
            signal_e=self.signal_e,
            full_well_e=self.full_well_e,
            read_noise_e=self.read_noise_e,
            gain_e_per_dn=self.full_well_e / adc_max,
            bias_dn=self.bias_dn,
            adc_max_dn=jnp.asarray(adc_max, dtype=jnp.float64),
            roi_px=self.roi_px,
            window_px=self.window_px,
            samples=self.samples,
            label_iterations=self.label_iterations,
            max_bin_log2=self.max_bin_log2,
            max_exposure_gain=self.max_exposure_gain,
        )


class TargetParams(eqx.Module):
    """The target's shape and orientation (SI)."""

    semi_axes_m: Float[Array, "3"] = param(
        [3.0, 3.0, 3.0],
        toml="semi_axes_km",
        section="target",
        scale=1e3,
        length=3,
        lo=0.0,
        lo_open=True,
        hi=1e3,
        units="km",
        doc="Lambertian ellipsoid semi-axes (equal: sphere; Tempel 1 class 3 km)",
    )
    orientation_rad: Float[Array, "3"] = param(
        [0.0, 0.0, 0.0],
        toml="orientation_deg",
        section="target",
        convert=lambda deg: [math.radians(a) for a in deg],
        length=3,
        lo=-360.0,
        hi=360.0,
        units="deg",
        doc="rotation vector body -> inertial of the ellipsoid axes",
    )

    def model(self, sun_direction: Vector3) -> TargetModel:
        """The Lambertian ellipsoid lit from ``sun_direction`` (a unit vector)."""
        return TargetModel(self.semi_axes_m, small_rotation(self.orientation_rad), sun_direction)


def _model(truth: str, units: str, scale: float, what: str):
    """A field of the filter's noise model: negative (the default) means the truth's value."""
    return param(
        -1.0,
        section="navigation",
        toml=f"model_{truth}",
        scale=scale,
        lo=-1.0,
        hi=1e6,
        units=units,
        doc=f"1-sigma {what} the filter assumes; negative: the truth's errors.{truth}",
    )


class NavigationParams(eqx.Module):
    """The filter's process noise and prior, and the measurement front end."""

    process_noise_m2s3: Scalar = param(
        1e-18,
        section="navigation",
        lo=0.0,
        hi=1.0,
        units="m^2/s^3",
        doc="filter white-acceleration density (unmodelled forces)",
    )
    consider_attitude_bias: Scalar = param(
        True,
        section="navigation",
        doc="add the attitude-bias rotation to the initial covariance",
    )
    model_image_processing_rad: Scalar = _model(
        "image_processing_urad", "urad", URAD, "centroiding error"
    )
    model_attitude_noise_rad: Scalar = _model(
        "attitude_noise_urad", "urad", URAD, "attitude determination noise"
    )
    model_attitude_bias_rad: Scalar = _model(
        "attitude_bias_urad", "urad", URAD, "attitude determination bias"
    )
    model_accel_bias_mps2: Scalar = _model("accel_bias_ug", "ug", UG, "accelerometer bias")
    model_accel_noise_mps2: Scalar = _model("accel_noise_ug", "ug", UG, "accelerometer noise")
    # The choices are the registered front ends, read when the schema is (ImpactorSystem).
    measurement: str = param(
        "noise",
        section="navigation",
        choices=("noise", "image"),
        doc="noise: LOS + Gaussian error; image: rendered frame + seed 002 centroiding",
    )
    phase_correction: Scalar = param(
        True,
        section="navigation",
        doc="image: remove the Lambertian-sphere centre-of-brightness offset (phase angle)",
    )


class GuidanceTiming(eqx.Module):
    """The system-level guidance fields: control step, aim points, the times to go of the
    retarget and the cut-off, and the delivery tolerance (SI). The law's own gains are its
    ``[guidance.<law>]`` table. The times are Python floats: they set loop sizes and scheduled
    events."""

    dt_s: float = param(
        1.0,
        section="guidance",
        static=True,
        lo=0.01,
        hi=60.0,
        units="s",
        doc="control step; must divide the image interval (>= 0.01 s: finer than any "
        "attitude or thruster response the models resolve)",
    )
    aim_initial_m: Float[Array, "2"] = param(
        [0.0, 0.0],
        toml="aim_initial_km",
        section="guidance",
        scale=1e3,
        length=2,
        units="km",
        doc="aim point (B_T, B_R) before the retarget",
    )
    aim_final_m: Float[Array, "2"] = param(
        [1.0, 3.0],
        toml="aim_final_km",
        section="guidance",
        scale=1e3,
        length=2,
        units="km",
        doc="aim point (B_T, B_R) after the retarget",
    )
    retarget_tgo_s: float = param(
        750.0,
        section="guidance",
        static=True,
        lo=0.0,
        units="s",
        doc="nominal time to go at which the aim point changes; more than cutoff_tgo_s "
        "unless aim_final_km = aim_initial_km (a later change is never flown)",
    )
    cutoff_tgo_s: float = param(
        60.0,
        section="guidance",
        static=True,
        lo=0.0,
        units="s",
        doc="no burn in the last cutoff_tgo_s before the nominal impact; the control step "
        "that starts before the cut-off must end by the nominal impact",
    )
    miss_limit_m: Scalar = miss_limit_param()


class ImpactorParams(NamedTuple):
    """Every declared parameter of an impactor scenario, SI (one Module per group)."""

    approach: Approach
    spacecraft: Spacecraft
    dynamics: ImpactorDynamicsParams
    camera: CameraParams
    target: TargetParams
    navigation: NavigationParams
    guidance: GuidanceTiming
    errors: ImpactorErrors

    @classmethod
    def of(cls, config: dict) -> "ImpactorParams":
        """The parameters of a validated configuration."""
        return cls(*(from_scenario(m, config) for m in PARAMETER_MODULES))


PARAMETER_MODULES = tuple(ImpactorParams.__annotations__.values())
"""The impactor's parameter Modules, in the order of the schema's sections and fields."""


class Timeline(NamedTuple):
    """Mission times (s, from the start of the approach) and loop sizes of a scenario."""

    time_of_flight_s: float  # nominal, straight line to the B-plane
    retarget_time_s: float
    cutoff_time_s: float
    n_images: int  # images before the cut-off, one every image interval from t = 0
    steps_per_image: int  # control steps per image interval
    steps_after_cutoff: int  # control steps the last image interval leaves out


def timeline(p: ImpactorParams) -> Timeline:
    """The mission times and loop sizes of ``p``: the one place they are derived (the
    simulation's loops and the cost model both read them; the loop's sizes are
    :func:`~.schema.guided_loop`'s)."""
    tof = nominal_time_of_flight_s(
        [float(x) for x in p.approach.position_m], [float(x) for x in p.approach.velocity_mps]
    )
    g = p.guidance
    t_cut = mission_time_s(tof, g.cutoff_tgo_s)
    n_images, steps_per_image, steps_after_cutoff = guided_loop(
        t_cut, p.camera.image_interval_s, g.dt_s
    )
    return Timeline(
        time_of_flight_s=tof,
        retarget_time_s=mission_time_s(tof, g.retarget_tgo_s),
        cutoff_time_s=t_cut,
        n_images=n_images,
        steps_per_image=steps_per_image,
        steps_after_cutoff=steps_after_cutoff,
    )


__all__ = [
    "Approach",
    "Spacecraft",
    "ImpactorDynamicsParams",
    "CameraParams",
    "TargetParams",
    "NavigationParams",
    "GuidanceTiming",
    "ImpactorParams",
    "PARAMETER_MODULES",
    "Timeline",
    "timeline",
]
