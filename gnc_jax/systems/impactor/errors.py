"""Error sources of the impactor terminal phase (seed 000 Table 2), each declared once with
its scenario field: ``[errors]`` and the knowledge fields of ``[navigation]``."""

import equinox as eqx

from ..._types import Array, Float, Scalar
from ...constants import G0_MPS2
from ...params import param

URAD = 1e-6  # file urad -> rad
UG = 1e-6 * G0_MPS2  # file micro-g -> m/s^2


class ImpactorErrors(eqx.Module):
    """1-sigma error sources (seed 000 Table 2), SI: angles in rad, accelerations in m/s^2.

    ``[errors]`` and the knowledge fields of ``[navigation]``.
    """

    delivery_position_m: Scalar = param(
        10.0,
        toml="delivery_position_km",
        section="errors",
        scale=1e3,
        lo=0.0,
        hi=1e4,
        units="km",
        doc="1-sigma initial position delivery error, per axis",
    )
    knowledge_position_m: Float[Array, "3"] = param(
        [150.0, 8.0, 8.0],
        toml="knowledge_position_km",
        section="navigation",
        scale=1e3,
        length=3,
        lo=0.0,
        units="km",
        doc="1-sigma initial position knowledge along S, T, R",
    )
    knowledge_velocity_mps: Scalar = param(
        0.1,
        section="navigation",
        lo=0.0,
        hi=1e3,
        units="m/s",
        doc="1-sigma initial velocity knowledge per axis",
    )
    image_processing_rad: Scalar = param(
        10.0,
        toml="image_processing_urad",
        section="errors",
        scale=URAD,
        lo=0.0,
        hi=1e5,
        units="urad",
        doc="centroiding error of the noise front end (and the filter's model of it unless "
        "navigation.model_image_processing_urad is set)",
    )
    attitude_control_rad: Scalar = param(
        320.0,
        toml="attitude_control_urad",
        section="errors",
        scale=URAD,
        lo=0.0,
        hi=1e5,
        units="urad",
        doc="camera and thrust pointing error",
    )
    attitude_bias_rad: Scalar = param(
        100.0,
        toml="attitude_bias_urad",
        section="errors",
        scale=URAD,
        lo=0.0,
        hi=1e5,
        units="urad",
        doc="attitude determination bias (constant per run)",
    )
    attitude_noise_rad: Scalar = param(
        30.0,
        toml="attitude_noise_urad",
        section="errors",
        scale=URAD,
        lo=0.0,
        hi=1e5,
        units="urad",
        doc="attitude determination random error (per image)",
    )
    camera_misalignment_rad: Scalar = param(
        0.0,
        toml="camera_misalignment_urad",
        section="errors",
        scale=URAD,
        lo=0.0,
        hi=1e5,
        units="urad",
        doc="camera boresight misalignment from the attitude reference, per axis: drawn once "
        "per run, rotates every image's line of sight; not known to the filter",
    )
    accel_bias_mps2: Scalar = param(
        50.0,
        toml="accel_bias_ug",
        section="errors",
        scale=UG,
        lo=0.0,
        hi=1e6,
        units="ug",
        doc="accelerometer bias (constant per run)",
    )
    accel_noise_mps2: Scalar = param(
        10.0,
        toml="accel_noise_ug",
        section="errors",
        scale=UG,
        lo=0.0,
        hi=1e6,
        units="ug",
        doc="accelerometer white noise",
    )
    burn_magnitude_frac: Scalar = param(
        2.0,
        toml="burn_magnitude_pct",
        section="errors",
        convert=lambda pct: pct / 100.0,
        lo=0.0,
        hi=50.0,
        units="%",
        doc="burn execution (thrust magnitude) error, drawn per firing",
    )


__all__ = ["ImpactorErrors"]
