"""The intercept's navigation: the filter's initial :class:`~.state.Estimate`, its LOS update
at every image and its mean prediction at every guidance step.

Seed 004 Table 4 gives knowledge errors but no navigation; the filter is the impactor's camera,
LOS front end and EKF (``navigation.camera``, ``navigation.measurements``, ``navigation.ekf``)
in the packed, sequential form of ``navigation.packed_ekf``.
"""

import jax
import jax.numpy as jnp

from ..._numerics import as_array, computed_once
from ..._types import Array, Float, PRNGKeyArray, Vector3
from ...navigation.camera import camera_axes
from ...navigation.ekf import NIS_BOUND_1DOF, NIS_BOUND_2DOF, NavEstimate
from ...navigation.measurements import Exposure
from ...navigation.packed_ekf import (
    ANGLE_NOISE_FLOOR_RAD,
    FULL,
    PLANAR,
    PackedCovariance,
    apply_gain,
    los_gain,
    pack,
    predict_los_packed,
    propagate_packed,
    unpack,
)
from .draws import front_end_key
from .state import Estimate, PNSimulation


def initial_estimate(sim: PNSimulation, know_pos: Vector3, know_vel: Vector3) -> Estimate:
    """The filter at t = 0: the nominal state plus the knowledge errors (``know_pos``,
    ``know_vel`` in the frame ``sim.los_frame0``), its covariance their 1-sigma values."""
    err = sim.errors
    frame = sim.los_frame0
    y0 = sim.y0
    r_hat, v_hat = y0.r + frame.T @ know_pos, y0.v + frame.T @ know_vel
    sig_p = jnp.maximum(err.knowledge_position_m, 1.0)  # a floor keeps P positive definite
    sig_v = jnp.maximum(err.knowledge_velocity_mps, 1e-6)
    p_pos = frame.T @ jnp.diag(sig_p**2) @ frame
    p0 = jax.scipy.linalg.block_diag(p_pos, sig_v**2 * jnp.eye(3))
    return Estimate(r_hat, v_hat, pack(p0, PLANAR if sim.planar else FULL))


def take_image(
    sim: PNSimulation,
    r_hat: Vector3,
    v_hat: Vector3,
    p: PackedCovariance,
    r_true: Vector3,
    w: Float[Array, "2"],
    key: PRNGKeyArray,
):
    """One LOS measurement and the gain of its EKF update: the camera points at the estimated
    target direction (x_c = h x boresight lies in the orbit plane), the attitude error is white
    angle noise of the front end (``sim.measurement``); the filter's measurement noise is
    ``sim.model_attitude_rad`` (the same unless ``navigation.model_attitude_urad`` is set).
    ``w``: the image's two measurement normals; ``key``: for front ends that draw more.

    The update is ``navigation.ekf.ekf_update`` of ``predict_los`` in packed, sequential form
    (``navigation.packed_ekf``); a planar run takes the in-plane angle only (the out-of-plane
    one is exact and would change only out-of-plane entries, see ``packed_ekf.los_update``).
    Returns the :class:`~gnc_jax.navigation.packed_ekf.LOSGain` (zero for a rejected image)
    and whether the image was used; the caller updates the covariance (``apply_gain``, fused
    with the propagation).
    """
    # The camera's axes as three row vectors, each product written per row: the stacked
    # matrix is built only for the front end's exposure (read row-wise it is never stored).
    rows = camera_axes(-r_hat, sim.context.reference_normal)
    c_cam = jnp.stack([as_array(row) for row in rows])
    r_var = jnp.maximum(sim.model_attitude_rad, ANGLE_NOISE_FLOOR_RAD) ** 2
    h_r, predicted = predict_los_packed(rows, r_hat, p, r_var)
    nav = NavEstimate(jnp.concatenate([as_array(r_hat), as_array(v_hat)]), unpack(p))
    meas = sim.measurement(Exposure(-as_array(r_true), c_cam, c_cam), nav, predicted, w, key)
    angles = 1 if sim.planar else 2
    innovation = [meas.z[a] - predicted.z[a] for a in range(2)]
    return los_gain(r_hat, v_hat, p, h_r, innovation, r_var, angles, meas.valid), meas.valid


def image_update(
    sim: PNSimulation,
    key: PRNGKeyArray,
    i,
    t,
    estimate: Estimate,
    r_true: Vector3,
    w: Float[Array, "2"],
) -> tuple[Estimate, Array, Array]:
    """The estimate after image ``i`` (at time ``t``, measurement normals ``w``), its
    covariance propagated over the image interval; whether the image was used, and whether
    its innovation lay beyond the chi-square 99.9 % bound (``navigation.ekf.NIS_BOUND_*``,
    for the angles taken)."""
    # The gain once into memory; the covariance update then reads it in one elementwise pass
    # with the propagation (P is not read by the guidance steps in between). The front end's
    # key is derived inside the fenced branch, where XLA drops it when the front end draws
    # nothing (derived outside, its two threefry hashes ran at every image: 15 ns of a 190 ns
    # guidance step).
    gain, used = computed_once(  # live: the float time (an integer ``i == i`` folds to true)
        lambda *a: take_image(sim, *a, front_end_key(key, i)),
        t,
        estimate.r_hat,
        estimate.v_hat,
        estimate.p,
        r_true,
        w,
    )
    image_dt = sim.context.dt_s * sim.steps_per_image
    p = propagate_packed(apply_gain(estimate.p, gain.terms), image_dt, sim.process_noise_m2s3)
    bound = NIS_BOUND_1DOF if sim.planar else NIS_BOUND_2DOF
    return Estimate(gain.r, gain.v, p), used, used & (gain.nis > bound)


def predict_mean(r_hat: Vector3, v_hat: Vector3, dv_nav: Vector3, dt) -> tuple[Vector3, Vector3]:
    """The mean over one guidance step of ``dt`` (s): straight-line motion plus the velocity
    change ``dv_nav`` (the executed Δv and the modelled gravity over the step), applied as a
    constant acceleration (``navigation.ekf.propagate_state``)."""
    return r_hat + v_hat * dt + dv_nav * (0.5 * dt), v_hat + dv_nav


__all__ = ["image_update", "initial_estimate", "predict_mean", "take_image"]
