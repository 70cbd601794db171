"""The impactor's navigation: the camera pointed at the target, one image and its EKF update
on the packed covariance, the accelerometer's noise reaching the estimate, and the filter's
initial covariance with the attitude bias considered."""

import jax
import jax.numpy as jnp

from ..._numerics import matmul
from ..._types import Array, Float, Scalar, Vector3
from ...navigation.camera import camera_axes, rotate_rows, small_rotation_entries
from ...navigation.ekf import NavEstimate
from ...navigation.measurements import Exposure, Measurement
from ...navigation.packed_ekf import (
    ANGLE_NOISE_FLOOR_RAD,
    LOSGain,
    PackedCovariance,
    apply_gain,
    los_gain,
    pack,
    predict_los_packed,
    unpack,
)
from .state import ImpactorSimulation


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


def camera_attitudes(
    sim: ImpactorSimulation,
    r_hat: Vector3,
    attitude_bias_rad,
    w,
    misalignment_rad=None,
    rotation_entries=small_rotation_entries,
) -> tuple:
    """``(c_true, c_est)``, each the three rows of a camera attitude C_cI: the camera pointed
    at the estimated target direction with attitude-control error (``w[2:5]``) and rotated by
    its misalignment ``misalignment_rad`` (None: none), and the attitude the navigation
    believes (bias + knowledge error ``w[5:8]``, of the attitude reference: the filter does
    not know the misalignment).

    The attitude errors' rotations come from power series (``small_rotation_entries``: no
    trigonometry), composed row by row. ``rotation_entries``: how a rotation's entries are
    computed (a batched caller computes them once into memory with
    :func:`~gnc_jax._numerics.computed_once`: left to fusion, both series are recomputed for
    every component of every row of both attitudes).
    """
    err = sim.errors
    cmd = camera_axes(-r_hat, sim.context.c_bi[2])
    c_true = rotate_rows(rotation_entries(err.attitude_control_rad * w[2:5]), cmd)
    knowledge = attitude_bias_rad + err.attitude_noise_rad * w[5:8]
    c_est = rotate_rows(rotation_entries(knowledge), c_true)
    if misalignment_rad is not None:
        c_true = rotate_rows(rotation_entries(misalignment_rad), c_true)
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
    model = sim.noise_model
    c_true, c_est = attitudes
    r_var = jnp.maximum(
        model.image_processing_rad**2 + model.attitude_noise_rad**2, ANGLE_NOISE_FLOOR_RAD**2
    )
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


@jax.custom_jvp
def _sqrt_nonnegative(x):
    """sqrt(max(x, 0)), with slope 0 where that is 0.

    C - B^2/A (:func:`accel_noise`) is zero in exact arithmetic when the engine fired in one
    control step of the interval, and rounds to either side of zero. The square root's slope
    is infinite there: a relaxed law's tangent would be 0 x inf = NaN, and so would the
    gradient of every batch holding such a run. The values are the plain expression's."""
    return jnp.sqrt(jnp.maximum(x, 0.0))


@_sqrt_nonnegative.defjvp
def _sqrt_nonnegative_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    y = _sqrt_nonnegative(x)
    positive = y > 0.0
    return y, jnp.where(positive, dx / (2.0 * jnp.where(positive, y, 1.0)), 0.0)


def accel_noise(sigma_dv, moments, u):
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
    gamma = _sqrt_nonnegative(jnp.where(ok, c - beta**2, 0.0))
    dr = sigma_dv * (beta * u[:3] + gamma * u[3:])
    return dr, dv


__all__ = [
    "accel_noise",
    "attitude_bias_covariance",
    "camera_attitudes",
    "image_update",
    "take_image",
]
