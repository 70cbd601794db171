"""EKF on the impactor's relative position and velocity (seed 002 §3.2, SPEC §5).

State x = (r, v): impactor relative to the target, inertial (the B-plane frame is a constant
rotation of it). Between images the model is straight-line motion plus the Δv the accelerometer
measures during burns; each image gives the two tangent-plane angles of the target's centroid.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._types import Array, Covariance6, Float, Matrix3, State6, Vector3
from .camera import los_angles

_S_FLOOR = 1e-200  # added to the innovation covariance's diagonal (see ekf_update)


class NavEstimate(NamedTuple):
    x: State6  # (r m, v m/s)
    p: Covariance6

    @property
    def r(self) -> Vector3:
        return self.x[:3]

    @property
    def v(self) -> Vector3:
        return self.x[3:]


def propagate_state(nav: NavEstimate, dv_measured: Vector3, dt) -> NavEstimate:
    """Straight-line mean propagation over ``dt`` with a measured Δv applied uniformly."""
    r, v = nav.r, nav.v
    r_new = r + v * dt + 0.5 * dv_measured * dt
    v_new = v + dv_measured
    return NavEstimate(jnp.concatenate([r_new, v_new]), nav.p)


def propagate_covariance(p: Covariance6, dt, q_accel, q_dv) -> Covariance6:
    """P <- Phi P Phi^T + Q over ``dt`` for straight-line motion.

    Args:
        q_accel: white-acceleration spectral density (m^2/s^3), unmodelled forces.
        q_dv: variance of the accelerometer-measured Δv error over the interval (m^2/s^2 per
            axis), added to the velocity block (burn execution seen through the accelerometer).
    """
    eye = jnp.eye(3)
    phi = jnp.block([[eye, dt * eye], [jnp.zeros((3, 3)), eye]])
    q = q_accel * jnp.block([[dt**3 / 3 * eye, dt**2 / 2 * eye], [dt**2 / 2 * eye, dt * eye]])
    q = q + jnp.block([[jnp.zeros((3, 3)), jnp.zeros((3, 3))], [jnp.zeros((3, 3)), q_dv * eye]])
    return phi @ p @ phi.T + q


class MeasurementPrediction(NamedTuple):
    """What the filter expects of one measurement before it sees it.

    ``z`` = h(x_hat) the predicted measurement, ``jacobian`` H = dh/dx at x_hat, ``r_cov`` the
    measurement-noise covariance R, and ``s`` = H P H^T + R the innovation covariance (the
    image front end sizes its region of interest with it).
    """

    z: Float[Array, " m"]
    jacobian: Float[Array, "m 6"]
    r_cov: Float[Array, "m m"]
    s: Float[Array, "m m"]


def predict_measurement(
    nav: NavEstimate, h: Callable[[State6], Float[Array, " m"]], r_cov: Float[Array, "m m"]
) -> MeasurementPrediction:
    """Predicted measurement h(x_hat), its Jacobian (``jax.jacfwd``) and the innovation
    covariance S = H P H^T + R of the measurement function ``h`` with noise covariance ``r_cov``."""
    z_pred = h(nav.x)
    hj = jax.jacfwd(h)(nav.x)
    s = hj @ nav.p @ hj.T + r_cov
    return MeasurementPrediction(z_pred, hj, r_cov, s)


def ekf_update(
    nav: NavEstimate, z: Float[Array, " m"], predicted: MeasurementPrediction, valid=True
) -> tuple[NavEstimate, Float[Array, " m"]]:
    """EKF update with the measurement ``z`` (Joseph form, any measurement function).

    K = P H^T S^-1, x <- x + K (z - h(x)), P <- (I - K H) P (I - K H)^T + K R K^T
    (symmetrised), with ``predicted`` from :func:`predict_measurement`. When ``valid`` is false
    (a rejected image) the estimate is returned unchanged.

    Returns:
        The updated estimate and the innovation z - h(x_hat).
    """
    hj, r_meas, s = predicted.jacobian, predicted.r_cov, predicted.s
    # A filter that is certain (P = 0) of a noiseless measurement (R = 0) has S = 0 and gains
    # nothing from the image: K = P H^T S^-1 = 0. The floor (far below any real S) keeps the
    # solve finite there and changes nothing elsewhere.
    s = s + _S_FLOOR * jnp.eye(s.shape[0])
    k = jnp.linalg.solve(s, hj @ nav.p).T
    innovation = z - predicted.z
    x = nav.x + k @ innovation
    ikh = jnp.eye(nav.x.shape[0]) - k @ hj
    p = ikh @ nav.p @ ikh.T + k @ r_meas @ k.T
    p = 0.5 * (p + p.T)
    updated = jax.tree_util.tree_map(lambda a, b: jnp.where(valid, a, b), NavEstimate(x, p), nav)
    return updated, innovation


def los_model(c_ci: Matrix3) -> Callable[[State6], Float[Array, "2"]]:
    """Measurement function of the tangent-plane angles: the LOS from the impactor to the
    target, -r, through the camera attitude ``c_ci`` the navigation believes."""

    def h(x):
        return los_angles(c_ci, -x[:3])

    return h


def update_los(
    nav: NavEstimate, z: Float[Array, "2"], c_ci: Matrix3, sigma_rad
) -> tuple[NavEstimate, Float[Array, "2"]]:
    """EKF update with the tangent-plane angles ``z`` of the target (rad), white noise
    ``sigma_rad`` per axis: :func:`ekf_update` of :func:`los_model`.

    Returns:
        The updated estimate and the innovation (rad).
    """
    predicted = predict_measurement(nav, los_model(c_ci), sigma_rad**2 * jnp.eye(2))
    return ekf_update(nav, z, predicted)
