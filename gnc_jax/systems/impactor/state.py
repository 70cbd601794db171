"""What one impactor run is made of: its data (:class:`ImpactorSimulation`), the parts of its
loop state (a :class:`~gnc_jax.systems.loop.LoopState` of the truth
:class:`~gnc_jax.dynamics.impactor.ImpactorState`, :class:`Estimate`, the law's state,
:class:`EngineMemory` and :class:`ImpactorTally`), its outcome and its trace.

Vectors that the control step reads are carried whole: the estimate as ``r_hat``, ``v_hat``
(not one 6-vector), the execution error as magnitude and pointing. Under ``vmap`` a slice of a
carried (batch, 6) array along its short axis is a strided read that XLA on CPU does not
vectorise (measured 5x slower for the LOS step). The covariance is carried as its 21 unique
entries, each a contiguous batch vector (``navigation.packed_ekf``: the dense (batch, 6, 6)
update measured half the image step's time).
"""

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from ..._numerics import V3
from ..._types import Array, Scalar, Vector3
from ...dynamics.impactor import Engine, RelativeDynamics
from ...guidance.impactor.base import ImpactorGuidanceContext
from ...navigation.ekf import NavEstimate
from ...navigation.measurements import AbstractMeasurement, GaussianLOSMeasurement
from ...navigation.packed_ekf import PackedCovariance, unpack
from ...navigation.render import CameraModel, TargetModel
from .errors import ImpactorErrors


class ImpactorSimulation(eqx.Module):
    """Everything one impactor run needs except the guidance law and the random key.

    Attributes:
        r0_m, v0_mps: nominal initial state of the impactor relative to the target, inertial.
        context: on-board mission data (B-plane frame, aim points, engine, timing).
        dynamics: true differential gravity; engine: true nominal engine; mass_kg: initial mass;
        propellant_kg: usable propellant (a run that burns more is flagged ``propellant``).
        miss_limit_m: delivery tolerance (a run whose B-plane miss is larger reads ``missed``).
        errors: 1-sigma error sources of the truth (what the draws scale).
        noise_model: the error sources as the filter models them (measurement noise, the
            accelerometer's Δv error, the attitude-bias consider term): ``errors`` with the
            ``navigation.model_*`` fields that are set.
        focal_length_m: camera focal length.
        process_noise_m2s3: white-acceleration density of the filter's process noise.
        consider_attitude_bias: 1.0 to add the attitude-bias rotation to the filter's initial
            covariance (:func:`~.navigation.attitude_bias_covariance`), 0.0 to ignore it.
        n_images, steps_per_image: loop sizes (static); steps_after_cutoff: control steps the
            last image interval leaves out so that the loop ends at the cut-off (static, 0 when
            the image interval divides the time to the cut-off); coast_steps: RK4 steps of the
            final coast.
        camera_misaligned: whether the camera misalignment is drawn and applied (static, as the
            dynamics' terms: computed only when its sigma is nonzero).
        measurement: the LOS measurement front end (a registered
            :class:`~gnc_jax.navigation.measurements.AbstractMeasurement`, chosen by
            ``navigation.measurement``): Gaussian LOS noise or rendered frames.
        camera, target: the scenario's camera/detector and target models (the image front end
            holds its own; these are kept for the report's frame figure).
        reverse_mode: the closed loop's fenced computations (``computed_once``) carry their
            own reverse-mode rules, which forward mode refuses (static; set by
            ``ImpactorSystem.reverse_mode``). The values agree either way (to rounding).
    """

    r0_m: Vector3
    v0_mps: Vector3
    context: ImpactorGuidanceContext
    dynamics: RelativeDynamics
    engine: Engine
    mass_kg: Scalar
    propellant_kg: Scalar
    miss_limit_m: Scalar
    errors: ImpactorErrors
    noise_model: ImpactorErrors
    focal_length_m: Scalar
    process_noise_m2s3: Scalar
    consider_attitude_bias: Scalar
    n_images: int = eqx.field(static=True)
    steps_per_image: int = eqx.field(static=True)
    steps_after_cutoff: int = eqx.field(static=True, default=0)
    coast_steps: int = eqx.field(static=True, default=4)
    camera_misaligned: bool = eqx.field(static=True, default=False)
    reverse_mode: bool = eqx.field(static=True, default=False)
    measurement: AbstractMeasurement = eqx.field(
        default_factory=lambda: GaussianLOSMeasurement(jnp.asarray(10e-6))
    )
    camera: CameraModel = eqx.field(default_factory=CameraModel)
    target: TargetModel = eqx.field(
        default_factory=lambda: TargetModel(
            jnp.full(3, 3e3), jnp.eye(3), jnp.array([1.0, 0.0, 0.0])
        )
    )


class Estimate(NamedTuple):
    """What navigation believes, and what the accelerometer has integrated since the last
    image (it reaches the mean and the covariance at the interval's end: ``accel_noise``,
    ``propagate_packed``)."""

    r_hat: Vector3  # m, impactor relative to the target
    v_hat: Vector3  # m/s
    p: PackedCovariance  # the 21 unique entries of the 6x6 covariance
    accel_moments: tuple  # 3 scalars: sums of throttle^2 * (1, c, c^2) over the interval
    burn_time_image_s: Scalar  # burn time since the last image (covariance growth)

    @property
    def nav(self) -> "NavEstimate | ComponentNav":
        """The estimate a law reads: the dense one (6-vector mean, 6x6 covariance), or, with
        the mean carried by component, a :class:`ComponentNav` of the same values."""
        if isinstance(self.r_hat, V3):
            return ComponentNav(self.r_hat, self.v_hat, self.p)
        return NavEstimate(jnp.concatenate([self.r_hat, self.v_hat]), unpack(self.p))


class ComponentNav(NamedTuple):
    """The estimate as a law reads it where the loop carries the mean by component (reverse
    mode's control steps, :func:`~.step.image_step`): ``r`` and ``v`` as
    :class:`~gnc_jax._numerics.V3`, the covariance packed (a law reads its entries,
    ``nav.p[i, j]``). The same values as the dense :class:`~gnc_jax.navigation.ekf.NavEstimate`."""

    r: V3  # m
    v: V3  # m/s
    p: PackedCovariance


class EngineMemory(NamedTuple):
    """What the engine remembers between control steps: the last throttle (to see an
    ignition), the execution-error draws of the current firing, those that the interval's
    first and later ignitions will use (a row of the run's burn table, ``draws.burn_draws``),
    and the counters that pick them."""

    throttle_prev: Scalar
    exec_magnitude: Scalar  # standard normal of the current firing's magnitude error
    exec_pointing: Vector3  # standard normals of its pointing error (3 axes, see tilt)
    first_magnitude: Scalar  # execution draws of the interval's first ignition
    first_pointing: Vector3
    second_magnitude: Scalar  # ... and of its later ignitions
    second_pointing: Vector3
    ignitions_image: Array  # int, ignitions since the last image
    burn_intervals: Array  # int, image intervals so far in which the engine fired


class ImpactorTally(NamedTuple):
    """What the outcome counts along the way."""

    dv_mps: Scalar  # total achieved Δv magnitude (sum over burns)
    firings: Array  # int, engine ignitions
    burn_time_s: Scalar
    los_error_sq: Scalar  # sum of squared LOS measurement errors (rad^2) over used images
    images_used: Array  # int
    innovations_outside: Array  # int, used images with NIS > NIS_BOUND_2DOF


class ImpactorOutcome(NamedTuple):
    """Per-run results. Vectors of dispersion draws are in the B-plane frame (S, T, R)."""

    status: Array  # int, Status
    miss_m: Scalar
    miss_t_m: Scalar  # B_T - aim_T
    miss_r_m: Scalar
    b_t_m: Scalar
    b_r_m: Scalar
    dv_mps: Scalar  # total achieved Δv magnitude (sum over burns)
    firings: Array  # int, number of engine ignitions
    burn_time_s: Scalar
    fuel_kg: Scalar
    nav_position_error_m: Scalar  # |r_hat - r| at the end of guidance
    nav_sigma_b_m: Scalar  # 1-sigma B-plane mean position error of the filter at the end
    delivery_error_m: Vector3
    knowledge_position_error_m: Vector3
    knowledge_velocity_error_mps: Vector3
    attitude_bias_rad: Vector3
    accel_bias_mps2: Vector3
    los_error_rms_urad: Scalar  # per-axis RMS of (measured - true) LOS angles over used images
    images_rejected: Array  # int, images without a valid centroid (no filter update)
    # B-plane impact point in units of the target's silhouette (< 1: a hit, geometry.silhouette)
    silhouette_ratio: Scalar
    innovations_outside: Array  # int, used images whose innovation was beyond the chi2 99.9 %


class StepRecord(NamedTuple):
    """Control-rate trace of one run (for plots)."""

    t_s: Scalar
    throttle: Scalar
    r_m: Vector3
    v_mps: Vector3
    r_hat_m: Vector3
    v_hat_mps: Vector3
    law_state: tuple


__all__ = [
    "ComponentNav",
    "EngineMemory",
    "Estimate",
    "ImpactorOutcome",
    "ImpactorSimulation",
    "ImpactorTally",
    "StepRecord",
]
