"""What one intercept run is made of: its data (:class:`PNSimulation`), the parts of its loop
state (a :class:`~gnc_jax.systems.loop.LoopState` of the truth, :class:`Estimate`, the law's
state, :class:`PulseActuator` and :class:`PulseTally`), its outcome and its trace.
"""

from typing import NamedTuple

import equinox as eqx

from ..._types import Array, Float, Matrix3, Scalar, Vector3
from ...dynamics.impactor import Engine
from ...dynamics.intercept import InterceptDynamics, InterceptState
from ...guidance.intercept.apn import PNGuidanceContext
from ...navigation.measurements import AbstractMeasurement
from ...navigation.packed_ekf import PackedCovariance
from .params import PNErrors


class PNSimulation(eqx.Module):
    """Everything one intercept run needs except the guidance law and the random key.

    Attributes:
        y0: nominal initial truth (target heliocentric, impactor relative, mass).
        context: on-board data of the law; dynamics: true force model; engine: true engine.
        propellant_kg: usable propellant (a run that burns more is flagged ``propellant``).
        miss_limit_m: delivery tolerance (a run whose B-plane miss is larger reads ``missed``).
        errors: 1-sigma error sources; process_noise_m2s3: filter white-acceleration density.
        model_attitude_rad: the LOS angle noise the filter assumes (``errors.attitude_rad``
            unless ``navigation.model_attitude_urad`` is set).
        c_bi: B-plane frame (S, T, R) of the nominal approach; los_frame0: rows (along LOS,
            across it in the orbit plane, out of plane) at t = 0, for the knowledge errors.
        planar: keep every error in the orbit plane (static); nav_model: "ekf" or "perfect".
        n_images, steps_per_image, coast_steps: loop sizes (static).
        measurement: the LOS front end (Gaussian angle noise of the attitude error, zero out
            of plane when planar).
    """

    y0: InterceptState
    context: PNGuidanceContext
    dynamics: InterceptDynamics
    engine: Engine
    propellant_kg: Scalar
    miss_limit_m: Scalar
    errors: PNErrors
    process_noise_m2s3: Scalar
    model_attitude_rad: Scalar
    c_bi: Matrix3
    los_frame0: Matrix3
    measurement: AbstractMeasurement
    planar: bool = eqx.field(static=True)
    nav_model: str = eqx.field(static=True)
    n_images: int = eqx.field(static=True)
    steps_per_image: int = eqx.field(static=True)
    coast_steps: int = eqx.field(static=True, default=60)


class Estimate(NamedTuple):
    """The filter's belief: the mean carried as ``r_hat``, ``v_hat``, not one 6-vector (under
    ``vmap`` a slice of a carried (batch, 6) array along its short axis is a strided read that
    XLA on CPU does not vectorise), and the covariance as its unique entries, each a
    contiguous batch vector (``navigation.packed_ekf``). The loop carries ``()`` instead with
    perfect navigation."""

    r_hat: Vector3  # m, impactor relative to the target
    v_hat: Vector3  # m/s
    p: PackedCovariance  # the 21 unique entries of the 6x6 covariance (10 when planar)


class PulseActuator(NamedTuple):
    """What the thrusters remember between guidance steps: the last firing direction (to see
    a reversal) and the pointing error of the current pulse train (drawn at its ignition).
    The trigger's last state (to see an ignition) is the law's own ``engine_on``: carried
    once, not also here (a value carried twice is one more array in the loop and, on a GPU,
    one more copy kernel per step)."""

    direction_prev: Vector3
    pointing_error: Float[Array, "2"]  # rad, about the orbit normal (and across it in 3-D)


class PulseTally(NamedTuple):
    """What the outcome counts along the way."""

    dv_mps: Scalar  # total Δv magnitude (sum over pulses)
    firings: Array  # int, pulse trains: a new one at each ignition or thrust reversal
    ignitions: Array  # int, trigger off -> on transitions
    pulses: Array  # int, guidance steps with the engine on
    last_firing_s: Scalar  # mission time of the last pulse (0 if none)
    images_used: Array  # int, images that updated the filter
    innovations_outside: Array  # int, used images with NIS beyond the 99.9 % chi-square bound


class PNOutcome(NamedTuple):
    """Per-run results. B-plane miss components relative to the target's centre."""

    status: Array  # int, Status
    miss_m: Scalar
    miss_t_m: Scalar
    miss_r_m: Scalar
    dv_mps: Scalar  # total Δv magnitude (sum over pulses)
    firings: Array  # int, pulse trains: a new one at each ignition or thrust reversal
    ignitions: Array  # int, trigger off -> on transitions
    pulses: Array  # int, guidance steps with the engine on
    last_firing_s: Scalar  # mission time of the last pulse (0 if none)
    fuel_kg: Scalar
    nav_position_error_m: Scalar  # |r_hat - r| at the end of guidance
    knowledge_position_error_m: Vector3  # along LOS, across in-plane, out of plane
    knowledge_velocity_error_mps: Vector3  # same axes
    # B-plane miss over the capture radius of the spherical target (< 1: a hit, see
    # gnc_jax.geometry.silhouette)
    silhouette_ratio: Scalar
    images_rejected: Array  # int, images that gave no update (0 with navigation.model "perfect")
    innovations_outside: Array  # int, used images with NIS beyond the chi-square 99.9 % bound


class PNRecord(NamedTuple):
    """Guidance-rate trace of one run (Figs. 7-9)."""

    t_s: Scalar
    engine_on: Scalar
    command_mps2: Vector3  # continuous APN command A (eq. 11)
    coefficient: Scalar  # N (eq. 12)
    range_m: Scalar
    r_m: Vector3


__all__ = [
    "Estimate",
    "PNOutcome",
    "PNRecord",
    "PNSimulation",
    "PulseActuator",
    "PulseTally",
]
