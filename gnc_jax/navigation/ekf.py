"""EKF on the impactor's relative position and velocity (seed 002 §3.2).

State x = (r, v): impactor relative to the target, inertial (the B-plane frame is a constant
rotation of it). Between images the model is straight-line motion plus the Δv the accelerometer
measures during burns; each image gives the two tangent-plane angles of the target's centroid.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._numerics import matmul, matvec3
from .._types import Array, Covariance6, Float, Matrix3, State6, Vector3
from .camera import los_angles

_S_FLOOR = 1e-200  # added to the innovation covariance's diagonal (see ekf_update)

# When is navigation lost (Status.nav_lost)? A filter fed by its images uses most of them, and
# its normalised innovations squared, NIS = nu^T S^-1 nu, follow a chi-square law with m
# degrees of freedom (m = 2 LOS angles). Navigation is lost when
# * more than NAV_LOST_UNUSED of the images gave no update (rejected: nothing found, or the
#   window left the ROI), or
# * more than NAV_LOST_OUTSIDE of the used images had an innovation beyond the chi-square
#   99.9 % bound (NIS_BOUND_2DOF = -2 ln 0.001 = 13.8 for 2 degrees of freedom, NIS_BOUND_1DOF
#   = 10.8 for a planar filter's one angle): a consistent filter has 0.1 % of its images there,
#   one that has lost the target has most of them.
# The two fractions are "most": half.
NAV_LOST_UNUSED = 0.5
NAV_LOST_OUTSIDE = 0.5
NIS_BOUND_2DOF = 13.815510557964274  # chi2.ppf(0.999, 2) = -2 ln(1e-3)
NIS_BOUND_1DOF = 10.827566170662733  # chi2.ppf(0.999, 1)


def normalised_innovation_squared(innovation, s) -> Float[Array, ""]:
    """NIS = nu^T S^-1 nu of a 2-vector innovation with its 2x2 covariance, closed form."""
    det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
    a, b = innovation[0], innovation[1]
    q = s[1, 1] * a * a - (s[0, 1] + s[1, 0]) * a * b + s[0, 0] * b * b
    return q / jnp.maximum(det, 1e-300)


def navigation_lost(n_images, images_used, innovations_outside):
    """``Status.nav_lost`` condition (see NAV_LOST_* above)."""
    unused = n_images - images_used
    return (unused > NAV_LOST_UNUSED * n_images) | (
        innovations_outside > NAV_LOST_OUTSIDE * images_used
    )


class NavEstimate(NamedTuple):
    x: State6  # (r m, v m/s)
    # 6x6, or a filter's packed form (``packed_ekf.PackedCovariance``) where the reader reads
    # it entry by entry (``p[i, j]`` for Python ints)
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


def _symmetric(entry, n: int) -> Float[Array, "n n"]:
    """The n x n symmetric matrix whose (i, j) entry, i <= j, is ``entry(i, j)``."""
    upper = {(i, j): entry(i, j) for i in range(n) for j in range(i, n)}
    return jnp.stack(
        [jnp.stack([upper[(min(i, j), max(i, j))] for j in range(n)]) for i in range(n)]
    )


def propagate_covariance(p: Covariance6, dt, q_accel, q_dv) -> Covariance6:
    """P <- Phi P Phi^T + Q over ``dt`` for straight-line motion.

    Args:
        q_accel: white-acceleration spectral density (m^2/s^3), unmodelled forces.
        q_dv: variance of the accelerometer-measured Δv error over the interval (m^2/s^2 per
            axis), added to the velocity block (burn execution seen through the accelerometer).

    Written out entry by entry (Phi = [[I, dt I], [0, I]]): under ``vmap`` these are a few
    fused elementwise loops over the batch instead of batched 6x6 products.
    """
    q_rr, q_rv, q_vv = q_accel * dt**3 / 3.0, q_accel * dt**2 / 2.0, q_accel * dt + q_dv

    def entry(i, j):
        if j < 3:  # both position (i <= j)
            v = p[i, j] + dt * (p[i, j + 3] + p[i + 3, j]) + dt * dt * p[i + 3, j + 3]
            return v + q_rr if i == j else v
        if i < 3:  # position-velocity
            v = p[i, j] + dt * p[i + 3, j]
            return v + q_rv if j == i + 3 else v
        return p[i, j] + q_vv if i == j else p[i, j]

    return _symmetric(entry, 6)


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
    s = matmul(matmul(hj, nav.p), hj.T) + r_cov
    return MeasurementPrediction(z_pred, hj, r_cov, s)


def predict_los(
    nav: NavEstimate, c_ci: Matrix3, r_cov: Float[Array, "2 2"]
) -> MeasurementPrediction:
    """:func:`predict_measurement` of :func:`los_model` with its Jacobian in closed form.

    With x_c = C (-r) and z = (x_c[0], x_c[1]) / x_c[2]: dz/dr = -(C[:2] - z C[2]) / x_c[2] and
    dz/dv = 0, so S = H_r P_rr H_r^T + R needs only the position block.
    """
    xc = matvec3(c_ci, -nav.r)
    inv = 1.0 / xc[2]
    z = xc[:2] * inv
    h_r = -(c_ci[:2] - z[:, None] * c_ci[2][None, :]) * inv
    hj = jnp.concatenate([h_r, jnp.zeros((2, 3))], axis=1)
    s = matmul(matmul(h_r, nav.p[:3, :3]), h_r.T) + r_cov
    return MeasurementPrediction(z, hj, r_cov, s)


def _inverse(s: Float[Array, "m m"]) -> Float[Array, "m m"]:
    """Inverse of a small symmetric positive-definite matrix: closed form for 1x1 and 2x2
    (no LAPACK call per run under ``vmap``), a solve otherwise."""
    m = s.shape[0]
    if m == 1:
        return 1.0 / s
    if m == 2:
        # Scaled by the larger diagonal entry first: a floor-sized S (1e-200 I, a certain
        # filter and a noiseless measurement) has a determinant below the smallest double.
        d = jnp.maximum(s[0, 0], s[1, 1])
        a, b, c, e = s[0, 0] / d, s[0, 1] / d, s[1, 0] / d, s[1, 1] / d
        adj = jnp.stack([jnp.stack([e, -b]), jnp.stack([-c, a])])
        return adj / ((a * e - b * c) * d)
    return jnp.linalg.solve(s, jnp.eye(m))


def ekf_update(
    nav: NavEstimate, z: Float[Array, " m"], predicted: MeasurementPrediction, valid=True
) -> tuple[NavEstimate, Float[Array, " m"]]:
    """EKF update with the measurement ``z`` (Joseph form, any measurement function).

    K = P H^T S^-1, x <- x + K (z - h(x)), P <- (I - K H) P (I - K H)^T + K R K^T
    (symmetric), with ``predicted`` from :func:`predict_measurement`. When ``valid`` is false
    (a rejected image) the estimate is returned unchanged.

    The Joseph form is expanded with S = H P H^T + R into P - K (P H^T)^T - (P H^T) K^T
    + K S K^T and written out entry by entry: O(n^2 m^2) scalar products that XLA fuses under
    ``vmap``, and a closed-form inverse of a 1x1 or 2x2 S (no LAPACK call per run).

    Returns:
        The updated estimate and the innovation z - h(x_hat).
    """
    hj, s = predicted.jacobian, predicted.s
    n, m = hj.shape[1], hj.shape[0]
    # A filter that is certain (P = 0) of a noiseless measurement (R = 0) has S = 0 and gains
    # nothing from the image: K = P H^T S^-1 = 0. The floor (far below any real S) keeps the
    # inverse finite there and changes nothing elsewhere.
    s = s + _S_FLOOR * jnp.eye(m)
    pht = matmul(nav.p, hj.T)  # P H^T, n x m
    k = matmul(pht, _inverse(s))
    ks = matmul(k, s)
    innovation = z - predicted.z
    x = jnp.stack([nav.x[i] + sum(k[i, a] * innovation[a] for a in range(m)) for i in range(n)])

    def entry(i, j):
        return nav.p[i, j] + sum(
            ks[i, a] * k[j, a] - k[i, a] * pht[j, a] - pht[i, a] * k[j, a] for a in range(m)
        )

    p = _symmetric(entry, n)
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
    predicted = predict_los(nav, c_ci, sigma_rad**2 * jnp.eye(2))
    return ekf_update(nav, z, predicted)
