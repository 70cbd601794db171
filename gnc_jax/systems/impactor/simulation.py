"""Closed-loop impactor terminal-phase simulation: truth, camera, EKF, guidance, engine.

One trajectory per call (`simulate`); Monte Carlo batches ``vmap`` it over per-run keys.
Time is mission time from the start of the approach (s). Two nested ``lax.scan`` loops: the
outer one at the image interval (image -> EKF update -> guidance ``plan``), the inner one at the
control step (guidance ``step`` -> engine -> RK4 truth step -> accelerometer -> EKF prediction).
The run ends at the guidance cut-off; the truth then coasts to the B-plane.
"""

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._numerics import V3, as_array, as_v3, computed_once, matmul, matvec3
from ..._random import stream_key, stream_normal
from ..._status import Status
from ..._types import Array, Float, PRNGKeyArray, Scalar, Vector3
from ...constants import GM_SUN_M3S2
from ...dynamics.impactor import (
    Engine,
    ImpactorState,
    RelativeDynamics,
    coast_to_b_plane,
    rk4,
    tilt_direction,
)
from ...geometry.bplane import b_plane_frame, check_b_plane_frame
from ...geometry.ellipse import b_plane_position_covariance, mean_position_error
from ...geometry.silhouette import focusing_factor, silhouette_matrix, silhouette_ratio
from ...guidance.impactor.base import AbstractImpactorGuidance, ImpactorGuidanceContext
from ...navigation.camera import camera_axes, rotate_rows, small_rotation_entries
from ...navigation.ekf import NIS_BOUND_2DOF, NavEstimate, navigation_lost
from ...navigation.measurements import (
    AbstractMeasurement,
    Exposure,
    GaussianLOSMeasurement,
    Measurement,
    MeasurementSetup,
    measurement_class,
)
from ...navigation.packed_ekf import (
    LOSGain,
    PackedCovariance,
    apply_gain,
    los_gain,
    pack,
    predict_los_packed,
    propagate_packed,
    unpack,
)
from ...navigation.render import CameraModel, TargetModel
from ..loop import flatten_trace, with_status
from .errors import ImpactorErrors
from .params import ImpactorParams, timeline


class ImpactorSimulation(eqx.Module):
    """Everything one impactor run needs except the guidance law and the random key.

    Attributes:
        r0_m, v0_mps: nominal initial state of the impactor relative to the target, inertial.
        context: on-board mission data (B-plane frame, aim points, engine, timing).
        dynamics: true differential gravity; engine: true nominal engine; mass_kg: initial mass;
        propellant_kg: usable propellant (a run that burns more is flagged ``propellant``).
        errors: 1-sigma error sources.
        focal_length_m: camera focal length.
        process_noise_m2s3: white-acceleration density of the filter's process noise.
        consider_attitude_bias: 1.0 to add the attitude-bias rotation to the filter's initial
            covariance (:func:`attitude_bias_covariance`), 0.0 to ignore it.
        n_images, steps_per_image: loop sizes (static); coast_steps: RK4 steps of the final coast.
        camera_misaligned: whether the camera misalignment is drawn and applied (static, as the
            dynamics' terms: computed only when its sigma is nonzero).
        measurement: the LOS measurement front end (a registered
            :class:`~gnc_jax.navigation.measurements.AbstractMeasurement`, chosen by
            ``navigation.measurement``): Gaussian LOS noise or rendered frames.
        camera, target: the scenario's camera/detector and target models (the image front end
            holds its own; these are kept for the report's frame figure).
    """

    r0_m: Vector3
    v0_mps: Vector3
    context: ImpactorGuidanceContext
    dynamics: RelativeDynamics
    engine: Engine
    mass_kg: Scalar
    propellant_kg: Scalar
    errors: ImpactorErrors
    focal_length_m: Scalar
    process_noise_m2s3: Scalar
    consider_attitude_bias: Scalar
    n_images: int = eqx.field(static=True)
    steps_per_image: int = eqx.field(static=True)
    coast_steps: int = eqx.field(static=True, default=4)
    camera_misaligned: bool = eqx.field(static=True, default=False)
    measurement: AbstractMeasurement = eqx.field(
        default_factory=lambda: GaussianLOSMeasurement(jnp.asarray(10e-6))
    )
    camera: CameraModel = eqx.field(default_factory=CameraModel)
    target: TargetModel = eqx.field(
        default_factory=lambda: TargetModel(
            jnp.full(3, 3e3), jnp.eye(3), jnp.array([1.0, 0.0, 0.0])
        )
    )


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


class _Carry(NamedTuple):
    """State of one run between control steps.

    Vectors that the control step reads are carried whole: the estimate as ``r_hat``,
    ``v_hat`` (not one 6-vector), the execution error as magnitude and pointing. Under
    ``vmap`` a slice of a carried (batch, 6) array along its short axis is a strided read that
    XLA on CPU does not vectorise (measured 5x slower for the LOS step). The covariance is
    carried as its 21 unique entries, each a contiguous batch vector (``navigation.packed_ekf``:
    the dense (batch, 6, 6) update measured half the image step's time).
    """

    truth: ImpactorState
    r_hat: Vector3
    v_hat: Vector3
    p: PackedCovariance
    law_state: tuple
    throttle_prev: Scalar
    exec_magnitude: Scalar  # standard normal of the current firing's magnitude error
    exec_pointing: Vector3  # standard normals of its pointing error (3 axes, see tilt)
    first_magnitude: Scalar  # execution draws of the interval's first ignition
    first_pointing: Vector3
    second_magnitude: Scalar  # ... and of its later ignitions
    second_pointing: Vector3
    ignitions_image: Array  # int, ignitions since the last image
    burn_intervals: Array  # int, image intervals so far in which the engine fired
    accel_moments: tuple  # 3 scalars: sums of throttle^2 * (1, c, c^2) over the interval
    dv_mps: Scalar
    firings: Array
    burn_time_s: Scalar
    burn_time_image_s: Scalar  # burn time since the last image (covariance growth)
    los_error_sq: Scalar  # sum of squared LOS measurement errors (rad^2) over used images
    images_used: Array  # int
    innovations_outside: Array  # int, used images with NIS > NIS_BOUND_2DOF

    @property
    def nav(self) -> NavEstimate:
        return NavEstimate(jnp.concatenate([self.r_hat, self.v_hat]), unpack(self.p))


# Random streams (gnc_jax._random): each kind of draw has its own stream, so adding a kind
# never changes the others. A run draws only what it uses, at the rate it is used:
# * once per run: delivery, knowledge (position, velocity), attitude bias, accelerometer bias,
#   camera misalignment (3 each);
# * once per image i (stream _IMAGES, index i), IMAGE_DRAWS standard normals:
#   [0:2] image-processing noise, [2:5] attitude control, [5:8] attitude knowledge;
# * once per run (stream _BURNS), a table of what only burns use, BURN_DRAWS normals per row:
#   [0:4] the execution error (magnitude, 3-axis pointing) of the interval's first ignition,
#   [4:8] that of its later ignitions, [8:14] the accelerometer's white noise integrated over
#   the interval (see _accel_noise). Row j belongs to the j-th image interval in which the
#   engine fires (64 rows: 16 min of burning at the paper's 15 s image interval).
# Nothing is drawn per control step: the engine fires in well under 1 % of the steps and in a
# few per cent of the image intervals, yet every vmapped lane computes whatever any lane might
# use: drawing the burns' normals with each image (18 normals instead of 8) cost more than
# the whole table, and one row fetched per image costs less than fetching separate ones.
_DELIVERY, _KNOW_POS, _KNOW_VEL, _ATT_BIAS, _ACC_BIAS, _IMAGES, _BURNS, _MISALIGNMENT = range(8)
IMAGE_DRAWS = 8
BURN_DRAWS = 14
# A run with more burning intervals than the table's rows reuses them cyclically. A third or
# later ignition within one interval repeats the second's draw: a law that chatters on and off
# within one interval fires again with the execution error it just had.
N_BURN_INTERVALS = 64


def image_draws(key: PRNGKeyArray, i) -> Float[Array, "8"]:
    """The standard normals of image ``i`` of the run with key ``key`` (layout above).

    Drawn in single precision (24-bit uniforms, so the tails end near 5.3 sigma) and used in
    float64: measured 1.7x cheaper than float64 draws, which were a third of the closed loop's
    time. The per-run draws (delivery, knowledge, biases), which set the dispersion, stay
    float64.
    """
    w = jax.random.normal(stream_key(key, _IMAGES, i), (IMAGE_DRAWS,), jnp.float32)
    return w.astype(jnp.float64)


def burn_draws(key: PRNGKeyArray) -> Float[Array, "N_BURN_INTERVALS 14"]:
    """The normals of a run's burns: row j for its j-th image interval with a burn (layout
    above)."""
    return stream_normal(key, _BURNS, (N_BURN_INTERVALS, BURN_DRAWS))


def run_draws(sim: "ImpactorSimulation", key: PRNGKeyArray) -> dict:
    """Every standard normal one run uses, by kind: what a peer implementation is fed to
    reproduce gnc_jax's outcomes run for run (``benchmarks/peers``)."""
    return dict(
        delivery=stream_normal(key, _DELIVERY),
        knowledge_position=stream_normal(key, _KNOW_POS),
        knowledge_velocity=stream_normal(key, _KNOW_VEL),
        attitude_bias=stream_normal(key, _ATT_BIAS),
        accel_bias=stream_normal(key, _ACC_BIAS),
        burns=burn_draws(key),
        images=jax.vmap(lambda i: image_draws(key, i))(jnp.arange(sim.n_images)),
    )


def _cross_matrix(a):
    return jnp.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def attitude_bias_covariance(r, v, sigma_bias_rad) -> Float[Array, "6 6"]:
    """Covariance of the relative state seen through an unknown constant attitude bias.

    A constant attitude-determination bias rotates every LOS measurement by the same small angle
    delta. Angles alone cannot tell that from the whole relative trajectory rotated about the
    target, (r, v) -> (r + delta x r, v + delta x v): the predicted miss is unchanged, but the
    velocity moves by |v| delta (about 1 m/s for 100 urad at 10.2 km/s), ten times the ground's
    0.1 m/s velocity knowledge. Adding this fully correlated term to the initial covariance
    ("considering" the bias) lets the 6-state filter accept that rotation instead of fighting it
    with an over-confident velocity prior.
    """
    g = -jnp.concatenate([_cross_matrix(r), _cross_matrix(v)])  # d(r, v)/d(delta), 6x3
    return sigma_bias_rad**2 * matmul(g, g.T)


def initial_conditions(sim: ImpactorSimulation, key: PRNGKeyArray):
    """Dispersed truth, initial estimate and constant error draws of one run."""
    err = sim.errors
    c_bi = sim.context.c_bi
    delivery = err.delivery_position_m * stream_normal(key, _DELIVERY)
    know_pos = err.knowledge_position_m * stream_normal(key, _KNOW_POS)  # S, T, R components
    know_vel = err.knowledge_velocity_mps * stream_normal(key, _KNOW_VEL)
    r_true = sim.r0_m + delivery
    truth = ImpactorState(r_true, sim.v0_mps, jnp.asarray(sim.mass_kg, float))
    x_hat = jnp.concatenate([r_true + matvec3(c_bi.T, know_pos), sim.v0_mps + know_vel])
    p_pos = matmul(c_bi.T * err.knowledge_position_m**2, c_bi)
    p0 = jax.scipy.linalg.block_diag(p_pos, err.knowledge_velocity_mps**2 * jnp.eye(3))
    p0 = p0 + sim.consider_attitude_bias * attitude_bias_covariance(
        sim.r0_m, sim.v0_mps, err.attitude_bias_rad
    )
    draws = dict(
        delivery_error_m=matvec3(c_bi, delivery),
        knowledge_position_error_m=know_pos,
        knowledge_velocity_error_mps=matvec3(c_bi, know_vel),
        attitude_bias_rad=err.attitude_bias_rad * stream_normal(key, _ATT_BIAS),
        accel_bias_mps2=err.accel_bias_mps2 * stream_normal(key, _ACC_BIAS),
    )
    return truth, NavEstimate(x_hat, p0), draws


def camera_misalignment(sim: ImpactorSimulation, key: PRNGKeyArray) -> Vector3:
    """The run's camera misalignment (rad, a rotation vector): fixed for the run, its own
    random stream, so the other draws do not change with it."""
    return sim.errors.camera_misalignment_rad * stream_normal(key, _MISALIGNMENT)


def camera_attitudes(
    sim: ImpactorSimulation, r_hat: Vector3, attitude_bias_rad, w, misalignment_rad=None
) -> tuple:
    """``(c_true, c_est)``, each the three rows of a camera attitude C_cI: the camera pointed
    at the estimated target direction with attitude-control error (``w[2:5]``) and rotated by
    its misalignment ``misalignment_rad`` (None: none), and the attitude the navigation
    believes (bias + knowledge error ``w[5:8]``, of the attitude reference: the filter does
    not know the misalignment).

    The attitude errors' rotations come from power series (``small_rotation_entries``: no
    trigonometry), composed row by row.
    """
    err = sim.errors
    cmd = camera_axes(-r_hat, sim.context.c_bi[2])
    c_true = rotate_rows(small_rotation_entries(err.attitude_control_rad * w[2:5]), cmd)
    knowledge = attitude_bias_rad + err.attitude_noise_rad * w[5:8]
    c_est = rotate_rows(small_rotation_entries(knowledge), c_true)
    if misalignment_rad is not None:
        c_true = rotate_rows(small_rotation_entries(misalignment_rad), c_true)
    return c_true, c_est


def image_update(
    sim: ImpactorSimulation,
    r_hat: Vector3,
    v_hat: Vector3,
    p: PackedCovariance,
    r_true: Vector3,
    attitudes: tuple,
    w,
    key,
) -> tuple[LOSGain, Measurement]:
    """One image and the gain of its EKF update (seed 002 §3.2), on the packed covariance:
    the :class:`~gnc_jax.navigation.packed_ekf.LOSGain` (updated mean, covariance terms for
    ``apply_gain``, NIS; zero gain for a rejected image) and the measurement.

    ``attitudes``: the true and believed camera attitudes (:func:`camera_attitudes`). The
    filter interprets the image through its attitude estimate, with the image-processing and
    attitude noise as its measurement noise (sigma^2 = sigma_ip^2 + sigma_att^2 per angle,
    independent). The front end (``sim.measurement``) sees the truth and the filter's
    prediction. ``w``: the image's two measurement normals; ``key``: for front ends that draw
    more (the renderer).

    The same filter as :func:`~gnc_jax.navigation.ekf.ekf_update` of
    :func:`~gnc_jax.navigation.ekf.predict_los` (its Joseph-form update is the reference the
    tests hold this to), written for batched CPU execution: the camera attitudes as row
    vectors, the update as two scalar updates on the 21 packed entries
    (``navigation.packed_ekf``).
    """
    err = sim.errors
    c_true, c_est = attitudes
    r_var = err.image_processing_rad**2 + err.attitude_noise_rad**2
    # predict_los through the believed attitude, row by row.
    h_r, predicted = predict_los_packed(c_est, r_hat, p, r_var)
    exposure = Exposure(-r_true, jnp.stack(c_true), jnp.stack(c_est))
    nav = NavEstimate(jnp.concatenate([r_hat, v_hat]), unpack(p))
    meas = sim.measurement(exposure, nav, predicted, w, key)
    innovation = [meas.z[a] - predicted.z[a] for a in range(2)]
    return los_gain(r_hat, v_hat, p, h_r, innovation, r_var, 2, meas.valid), meas


def take_image(
    sim: ImpactorSimulation, nav: NavEstimate, r_true: Vector3, attitude_bias_rad, w, key
) -> tuple[NavEstimate, Measurement, Scalar]:
    """:func:`image_update` on a dense estimate: the updated estimate, the measurement and
    its normalised innovation squared (NIS, against the innovation covariance); a rejected
    image leaves the estimate unchanged."""
    p = pack(nav.p)
    attitudes = camera_attitudes(sim, nav.r, attitude_bias_rad, w)
    gain, meas = image_update(sim, nav.r, nav.v, p, r_true, attitudes, w[:2], key)
    x = jnp.concatenate([gain.r, gain.v])
    return NavEstimate(x, unpack(apply_gain(p, gain.terms))), meas, gain.nis


def _accel_noise(sigma_dv, moments, u):
    """The accelerometer's white noise over one image interval, as it reaches the estimate.

    Each control step k adds throttle_k sigma dt n_k (n_k standard normal, independent per axis)
    to the measured Δv; at the end of the interval that step's noise has moved the estimated
    velocity by the same amount and the position by that amount times c_k = dt (S - k - 1/2).
    The sums over the interval are jointly Gaussian per axis with
    Var V = s^2 A, Cov(V, R) = s^2 B, Var R = s^2 C (s = sigma dt; A, B, C = sums of
    throttle^2 (1, c_k, c_k^2)), drawn exactly from the two normals ``u`` per axis. The
    estimate receives it at the end of the interval (before the next image) rather than step
    by step: the law's decisions within an interval see the accelerometer bias, not its white
    noise (10 ug: 1e-4 m/s per step, beside the filter's m/s-level velocity errors).

    Returns:
        ``(dr, dv)``: the position and velocity noise (m, m/s), inertial.
    """
    a, b, c = moments[0], moments[1], moments[2]
    ok = a > 0.0
    sa = jnp.sqrt(jnp.where(ok, a, 1.0))
    dv = jnp.where(ok, sigma_dv * sa, 0.0) * u[:3]
    beta = jnp.where(ok, b / sa, 0.0)
    gamma = jnp.sqrt(jnp.maximum(jnp.where(ok, c - beta**2, 0.0), 0.0))
    dr = sigma_dv * (beta * u[:3] + gamma * u[3:])
    return dr, dv


def _inline(fn, live, *args):
    """``fn(*args)``, left to XLA's fusion (the unfenced counterpart of computed_once)."""
    return fn(*args)


def _control_step(sim: ImpactorSimulation, law, accel_bias, record, carry: _Carry, inputs):
    """One control step: guidance ``step`` -> engine -> RK4 truth -> accelerometer -> EKF mean.

    The truth's vectors are :class:`V3` here (see :func:`_components`)."""
    ctx, err = sim.context, sim.errors
    dt = ctx.dt_s
    t, c_k = inputs  # c_k: s, weight of this step's Δv in the interval's end position
    # Once per step, not once per consumer loop (see computed_once).
    command, law_state = computed_once(
        lambda s, n: law.step(s, n, t, ctx), t, carry.law_state, carry.nav
    )
    throttle = command.throttle
    ignition = (throttle > 0.0) & (carry.throttle_prev <= 0.0)
    first = carry.ignitions_image == 0
    exec_magnitude = jnp.where(
        ignition,
        jnp.where(first, carry.first_magnitude, carry.second_magnitude),
        carry.exec_magnitude,
    )
    exec_pointing = jnp.where(
        ignition,
        jnp.where(first, carry.first_pointing, carry.second_pointing),
        carry.exec_pointing,
    )

    def engine_and_truth(truth, direction, throttle, exec_magnitude, exec_pointing):
        direction = tilt_direction(direction, err.attitude_control_rad * exec_pointing)
        magnitude = sim.engine.thrust_n * (1.0 + err.burn_magnitude_frac * exec_magnitude)
        thrust = (throttle * magnitude) * direction
        flow = throttle * sim.engine.mass_flow(1.0)
        return thrust, rk4(sim.dynamics, truth, thrust, flow, dt)

    # Fenced when the dynamics has terms to evaluate (four gravity evaluations per step, each
    # recomputed by every output's loop otherwise); without them the step is a few products
    # per component, cheaper left to fusion (measured 6 % of the loop).
    fence = computed_once if sim.dynamics.active else _inline
    thrust, truth = fence(
        engine_and_truth, t, carry.truth, command.direction, throttle, exec_magnitude, exec_pointing
    )
    # The accelerometer integrates the non-gravitational Δv while the engine fires; its white
    # noise reaches the estimate at the end of the interval (_accel_noise).
    per_mass = dt / (0.5 * (carry.truth.m + truth.m))
    dv_true = thrust * per_mass
    # |dv_true| without a square root: the tilted direction is a unit vector.
    magnitude = sim.engine.thrust_n * (1.0 + err.burn_magnitude_frac * exec_magnitude)
    dv_norm = (throttle * magnitude) * per_mass
    dv_meas = dv_true + (throttle * dt) * accel_bias
    # Straight-line mean propagation with the measured Δv applied uniformly (propagate_state).
    r_hat = carry.r_hat + carry.v_hat * dt + dv_meas * (0.5 * dt)
    v_hat = carry.v_hat + dv_meas
    th2 = throttle * throttle
    ign = ignition.astype(carry.ignitions_image.dtype)
    new = carry._replace(
        truth=truth,
        r_hat=r_hat,
        v_hat=v_hat,
        law_state=law_state,
        throttle_prev=throttle,
        exec_magnitude=exec_magnitude,
        exec_pointing=exec_pointing,
        ignitions_image=carry.ignitions_image + ign,
        accel_moments=(
            carry.accel_moments[0] + th2,
            carry.accel_moments[1] + th2 * c_k,
            carry.accel_moments[2] + th2 * c_k * c_k,
        ),
        dv_mps=carry.dv_mps + dv_norm,
        burn_time_image_s=carry.burn_time_image_s + throttle * dt,
    )
    rec = None
    if record:
        rec = StepRecord(t, throttle, as_array(truth.r), as_array(truth.v), r_hat, v_hat, law_state)
    return new, rec


def _image_step(
    sim: ImpactorSimulation, law, key, draws, burns, misalignment, record, carry: _Carry, i
):
    """One image interval: image -> EKF update -> guidance ``plan`` -> control steps ->
    accelerometer noise -> covariance propagation."""
    ctx, err = sim.context, sim.errors
    dt = ctx.dt_s
    n = sim.steps_per_image
    t = i * ctx.image_interval_s
    bias = draws["attitude_bias_rad"]

    # The image's normals and the camera attitudes they set, computed once into memory: left
    # to fusion, XLA recomputes a value in every consumer's loop, and the attitudes' products
    # feed every entry of the filter update (measured 4x the image step's time). The update
    # itself is fenced for the same reason (its gain feeds the 21 covariance entries); the
    # front end's key is derived inside it, where XLA drops it when the front end draws
    # nothing (the Gaussian one).
    def draws_and_attitudes(r_hat):
        w = image_draws(key, i)
        return w, camera_attitudes(sim, r_hat, bias, w, misalignment)

    w, attitudes = computed_once(draws_and_attitudes, t, carry.r_hat)
    gain, meas = computed_once(
        lambda *a: image_update(sim, *a, w[:2], jax.random.fold_in(stream_key(key, _IMAGES, i), 1)),
        t,
        carry.r_hat,
        carry.v_hat,
        carry.p,
        carry.truth.r,
        attitudes,
    )
    p = apply_gain(carry.p, gain.terms)
    nav = NavEstimate(jnp.concatenate([gain.r, gain.v]), unpack(p))
    law_state = law.plan(carry.law_state, nav, t, ctx)
    outside = (meas.valid & (gain.nis > NIS_BOUND_2DOF)).astype(carry.innovations_outside.dtype)
    los_error_sq = jnp.where(meas.valid, jnp.sum((meas.z - meas.z_true) ** 2), 0.0)
    z = jnp.zeros(())
    row = burns[carry.burn_intervals % N_BURN_INTERVALS]
    carry = carry._replace(
        r_hat=gain.r,
        v_hat=gain.v,
        p=p,
        law_state=law_state,
        first_magnitude=row[0],
        first_pointing=row[1:4],
        second_magnitude=row[4],
        second_pointing=row[5:8],
        ignitions_image=jnp.zeros_like(carry.ignitions_image),
        accel_moments=(z, z, z),
        burn_time_image_s=z,
        los_error_sq=carry.los_error_sq + los_error_sq,
        images_used=carry.images_used + meas.valid.astype(carry.images_used.dtype),
        innovations_outside=carry.innovations_outside + outside,
    )
    k = jnp.arange(n)
    inputs = (t + dt * k, dt * (n - k - 0.5))
    # The truth state crosses the control steps as components (V3): its RK4 step then fuses
    # into few elementwise kernels (measured 12 % of the whole closed loop, results bit for bit
    # equal); the rest of the carry stays in arrays, which the image step reads as vectors
    # and matrices (all of it as components measured slower overall).
    step = functools.partial(_control_step, sim, law, draws["accel_bias_mps2"], record)
    inner, rec = jax.lax.scan(step, carry._replace(truth=_components(carry.truth)), inputs)
    carry = inner._replace(truth=_arrays(inner.truth))
    burned = carry.accel_moments[0] > 0.0
    dr, dv = _accel_noise(err.accel_noise_mps2 * dt, carry.accel_moments, row[8:14])
    # Covariance: straight-line growth over the interval plus the accelerometer's Δv error.
    tb = carry.burn_time_image_s
    q_dv = err.accel_noise_mps2**2 * dt * tb + err.accel_bias_mps2**2 * tb**2
    p = propagate_packed(carry.p, ctx.image_interval_s, sim.process_noise_m2s3, q_dv)
    return carry._replace(
        r_hat=carry.r_hat + dr,
        v_hat=carry.v_hat + dv,
        p=p,
        burn_intervals=carry.burn_intervals + burned.astype(carry.burn_intervals.dtype),
        # the interval's totals (fewer outputs per control step: each is a kernel)
        firings=carry.firings + carry.ignitions_image,
        burn_time_s=carry.burn_time_s + tb,
    ), rec


def _components(tree):
    """Every 3-vector of ``tree`` as a :class:`V3`: the control steps' layout."""
    is_v3 = lambda x: isinstance(x, V3)  # noqa: E731
    return jax.tree_util.tree_map(
        lambda x: x if is_v3(x) or jnp.shape(x) != (3,) else as_v3(x), tree, is_leaf=is_v3
    )


def _arrays(tree):
    """Every :class:`V3` of ``tree`` as a (3,) array: the image steps' layout."""
    is_v3 = lambda x: isinstance(x, V3)  # noqa: E731
    return jax.tree_util.tree_map(lambda x: as_array(x), tree, is_leaf=is_v3)


def _outcome(sim: ImpactorSimulation, carry: _Carry, draws) -> ImpactorOutcome:
    """Coast the truth to the B-plane and collect the run's results (status unset)."""
    ctx = sim.context
    b, _ = coast_to_b_plane(sim.dynamics, carry.truth, ctx.c_bi, sim.coast_steps)
    miss = b - ctx.aim_final_m
    nav = carry.nav
    t_go = jnp.linalg.norm(nav.r) / jnp.linalg.norm(nav.v)
    sigma_b = mean_position_error(b_plane_position_covariance(nav.p, t_go, ctx.c_bi))
    return ImpactorOutcome(
        status=jnp.zeros((), jnp.int32),
        miss_m=jnp.linalg.norm(miss),
        miss_t_m=miss[0],
        miss_r_m=miss[1],
        b_t_m=b[0],
        b_r_m=b[1],
        dv_mps=carry.dv_mps,
        firings=carry.firings,
        burn_time_s=carry.burn_time_s,
        fuel_kg=sim.mass_kg - carry.truth.m,
        nav_position_error_m=jnp.linalg.norm(nav.r - carry.truth.r),
        nav_sigma_b_m=sigma_b,
        **draws,
        los_error_rms_urad=1e6
        * jnp.sqrt(carry.los_error_sq / jnp.maximum(2 * carry.images_used, 1)),
        images_rejected=(sim.n_images - carry.images_used).astype(jnp.int32),
        silhouette_ratio=silhouette_ratio(b, _silhouette(sim), _focusing(sim)),
        innovations_outside=carry.innovations_outside,
    )


def _silhouette(sim: ImpactorSimulation):
    """The target's shadow along S in the B-plane (m^2, :mod:`gnc_jax.geometry.silhouette`)."""
    return silhouette_matrix(sim.target.semi_axes_m, sim.target.c_bi, sim.context.c_bi)


def _focusing(sim: ImpactorSimulation):
    speed = jnp.linalg.norm(sim.v0_mps)
    return focusing_factor(sim.dynamics.mu_target, sim.target.mean_radius_m, speed)


def capture_silhouette(sim: ImpactorSimulation) -> Float[Array, "2 2"]:
    """The B-plane ellipse (shape matrix, m^2) whose inside is a hit: the silhouette widened
    by gravitational focusing."""
    return _silhouette(sim) * _focusing(sim) ** 2


def simulate(
    sim: ImpactorSimulation,
    law: AbstractImpactorGuidance,
    key: PRNGKeyArray,
    record: bool = False,
) -> tuple[ImpactorOutcome, StepRecord | None]:
    """Simulate one closed-loop impactor approach.

    Args:
        sim: scenario data (see :class:`ImpactorSimulation`).
        law: guidance law (an :class:`AbstractImpactorGuidance`).
        key: this run's key, ``jax.random.fold_in(root, run_index)``.
        record: also return the control-rate :class:`StepRecord` trace (static).

    Returns:
        ``(outcome, trace)``; ``trace`` is ``None`` unless ``record``.
    """
    truth0, nav0, draws = initial_conditions(sim, key)
    burns = burn_draws(key)
    z = jnp.zeros(())
    i0 = jnp.zeros((), jnp.int32)
    z3 = jnp.zeros(3)
    carry0 = _Carry(
        truth=truth0,
        r_hat=nav0.r,
        v_hat=nav0.v,
        p=pack(nav0.p),
        law_state=law.init(nav0, sim.context),
        throttle_prev=z,
        exec_magnitude=z,
        exec_pointing=z3,
        first_magnitude=z,
        first_pointing=z3,
        second_magnitude=z,
        second_pointing=z3,
        ignitions_image=i0,
        burn_intervals=i0,
        accel_moments=(z, z, z),
        dv_mps=z,
        firings=jnp.zeros((), jnp.int32),
        burn_time_s=z,
        burn_time_image_s=z,
        los_error_sq=z,
        images_used=jnp.zeros((), jnp.int32),
        innovations_outside=jnp.zeros((), jnp.int32),
    )
    misalignment = camera_misalignment(sim, key) if sim.camera_misaligned else None
    image_step = functools.partial(_image_step, sim, law, key, draws, burns, misalignment, record)
    carry, rec = jax.lax.scan(image_step, carry0, jnp.arange(sim.n_images))
    outcome = _outcome(sim, carry, draws)
    # A run whose navigation was lost ends nav_lost, ahead of what it then does to its fuel.
    lost = navigation_lost(sim.n_images, carry.images_used, carry.innovations_outside)
    failures = ((lost, Status.nav_lost), (outcome.fuel_kg > sim.propellant_kg, Status.propellant))
    return with_status(outcome, failures), flatten_trace(rec)


def measurement_setup(p: ImpactorParams) -> MeasurementSetup:
    """What the measurement front end is built from (SI), from the scenario's parameters."""
    return MeasurementSetup(
        camera=p.camera.model(),
        target=p.target.model(p.dynamics.sun_unit),
        image_processing_rad=p.errors.image_processing_rad,
        phase_correction=p.navigation.phase_correction,
    )


def build(scenario) -> ImpactorSimulation:
    """Simulation data of a validated impactor :class:`Scenario` (SI units, from the declared
    parameters :class:`~gnc_jax.systems.impactor.params.ImpactorParams`); the guidance law is
    built by the system from ``[guidance.<law>]`` (``systems.impactor``)."""
    p = ImpactorParams.of(scenario.config)
    a, sc, dy, g = p.approach, p.spacecraft, p.dynamics, p.guidance
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    check_b_plane_frame(a.velocity_mps, a.reference_normal)
    c_bi = b_plane_frame(a.velocity_mps, a.reference_normal)
    times = timeline(p)
    d = dy.sun_distance_m
    tide = GM_SUN_M3S2 / d**3 if d > 0 else 0.0
    sun = dy.sun_unit
    dynamics = RelativeDynamics.of(dy.mu_target_m3s2, tide, sun)
    engine = Engine(sc.thrust_n, sc.isp_s)
    context = ImpactorGuidanceContext(
        c_bi=c_bi,
        aim_initial_m=g.aim_initial_m,
        aim_final_m=g.aim_final_m,
        retarget_time_s=f(times.retarget_time_s),
        cutoff_time_s=f(times.cutoff_time_s),
        engine=engine,
        mass_kg=sc.mass_kg,
        dynamics=dynamics,
        dt_s=g.dt_s,
        image_interval_s=p.camera.image_interval_s,
    )
    setup = measurement_setup(p)
    return ImpactorSimulation(
        r0_m=a.position_m,
        v0_mps=a.velocity_mps,
        context=context,
        dynamics=dynamics,
        engine=engine,
        mass_kg=sc.mass_kg,
        propellant_kg=sc.propellant_kg,
        errors=p.errors,
        focal_length_m=p.camera.focal_length_m,
        process_noise_m2s3=p.navigation.process_noise_m2s3,
        consider_attitude_bias=p.navigation.consider_attitude_bias,
        n_images=times.n_images,
        steps_per_image=times.steps_per_image,
        coast_steps=dy.coast_steps,
        camera_misaligned=float(p.errors.camera_misalignment_rad) != 0.0,
        measurement=measurement_class(p.navigation.measurement).from_setup(setup),
        camera=setup.camera,
        target=setup.target,
    )
