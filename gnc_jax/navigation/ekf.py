"""EKF on the impactor's relative position and velocity (seed 002 §3.2, SPEC §5).

State x = (r, v): impactor relative to the target, inertial (the B-plane frame is a constant
rotation of it). Between images the model is straight-line motion plus the Δv the accelerometer
measures during burns; each image gives the two tangent-plane angles of the target's centroid.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._types import Array, Covariance6, Float, Matrix3, State6, Vector3
from .camera import los_angles


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


def update_los(
    nav: NavEstimate, z: Float[Array, "2"], c_ci: Matrix3, sigma_rad
) -> tuple[NavEstimate, Float[Array, "2"]]:
    """EKF update with the tangent-plane angles ``z`` of the target (rad).

    The predicted measurement is the LOS from the impactor to the target, -r, through the camera
    attitude the navigation believes (``c_ci``). Joseph-form covariance update.

    Returns:
        The updated estimate and the innovation (rad).
    """

    def h(x):
        return los_angles(c_ci, -x[:3])

    z_pred = h(nav.x)
    hj = jax.jacfwd(h)(nav.x)
    r_meas = sigma_rad**2 * jnp.eye(2)
    s = hj @ nav.p @ hj.T + r_meas
    k = jnp.linalg.solve(s, hj @ nav.p).T
    innovation = z - z_pred
    x = nav.x + k @ innovation
    ikh = jnp.eye(6) - k @ hj
    p = ikh @ nav.p @ ikh.T + k @ r_meas @ k.T
    p = 0.5 * (p + p.T)
    return NavEstimate(x, p), innovation
