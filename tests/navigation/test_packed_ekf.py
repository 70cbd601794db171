"""The packed, sequential LOS filter (``navigation.packed_ekf``) against the dense EKF of
``navigation.ekf`` (joint 2x2 update, Joseph form), numpy, and the planar reduction."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax.navigation.camera import camera_attitude
from gnc_jax.navigation.ekf import NavEstimate, ekf_update, predict_los, propagate_covariance
from gnc_jax.navigation.packed_ekf import (
    PLANAR,
    los_update,
    pack,
    packed_index,
    propagate_packed,
    unpack,
)


def _random_spd(rng, scales):
    a = rng.standard_normal((6, 6)) * np.asarray(scales)[:, None]
    return a @ a.T + np.diag(np.asarray(scales) ** 2 * 1e-3)


def _case(rng, planar=False):
    r = np.array([-4e8, 6e8, 0.0 if planar else 3e7])
    v = np.array([1e3, -1.02e4, 0.0 if planar else 5.0])
    scales = [1e5, 1e4, 1e4, 0.1, 0.1, 0.1]
    p = _random_spd(rng, scales)
    if planar:  # no out-of-plane correlation (as the planar intercept's knowledge errors)
        for i in (2, 5):
            for j in range(6):
                if j not in (2, 5):
                    p[i, j] = p[j, i] = 0.0
    return r, v, p


def test_pack_and_unpack_are_inverse():
    p = _random_spd(np.random.default_rng(0), [1.0] * 6)
    pk = pack(jnp.asarray(p))
    assert len(pk.entries) == 21
    np.testing.assert_array_equal(np.asarray(unpack(pk)), p)
    assert pk[4, 1] is pk.entries[packed_index(1, 4)]


def test_propagation_matches_dense_phi_p_phi_t_plus_q():
    rng = np.random.default_rng(1)
    p = _random_spd(rng, [1e5, 1e4, 1e4, 0.1, 0.1, 0.1])
    dt, q = 1.0, 1e-9
    phi = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    qm = q * np.block(
        [[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)], [dt**2 / 2 * np.eye(3), dt * np.eye(3)]]
    )
    ref = phi @ p @ phi.T + qm
    got = np.asarray(unpack(propagate_packed(pack(jnp.asarray(p)), dt, q)))
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max())
    dense = np.asarray(propagate_covariance(jnp.asarray(p), dt, q, 0.0))
    np.testing.assert_allclose(got, dense, rtol=1e-14, atol=0)


@pytest.mark.parametrize("seed", range(4))
def test_sequential_update_equals_the_joint_dense_update(seed):
    """Two scalar updates (prior linearisation) = the joint 2x2 EKF update, to 1e-10."""
    rng = np.random.default_rng(seed)
    r, v, p = _case(rng)
    nav = NavEstimate(jnp.asarray(np.concatenate([r, v])), jnp.asarray(p))
    c = camera_attitude(jnp.asarray(-r) + jnp.asarray([1e5, -2e5, 3e4]), jnp.array([0.0, 0, 1]))
    sigma = 3.2e-4
    pred = predict_los(nav, c, sigma**2 * jnp.eye(2))
    z = pred.z + jnp.asarray(rng.standard_normal(2) * 1e-3)
    ref, _ = ekf_update(nav, z, pred)
    h_r = pred.jacobian[:, :3]
    r1, v1, pk = los_update(nav.r, nav.v, pack(nav.p), h_r, z - pred.z, sigma**2)
    np.testing.assert_allclose(np.asarray(r1), np.asarray(ref.r), rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(np.asarray(v1), np.asarray(ref.v), rtol=1e-10, atol=1e-12)
    p1, p_ref = np.asarray(unpack(pk)), np.asarray(ref.p)
    scale = np.sqrt(np.outer(np.diag(p_ref), np.diag(p_ref)))
    assert np.abs((p1 - p_ref) / scale).max() < 1e-10
    # and against numpy's textbook form P - K S K^T
    hj = np.asarray(pred.jacobian)
    s = hj @ p @ hj.T + sigma**2 * np.eye(2)
    k = p @ hj.T @ np.linalg.inv(s)
    assert np.abs((p1 - (p - k @ s @ k.T)) / scale).max() < 1e-10


def _planar_prediction(seed):
    """A planar case's estimate, its LOS prediction (camera on the estimated target
    direction) and the angle noise sigma."""
    r, v, p = _case(np.random.default_rng(seed), planar=True)
    nav = NavEstimate(jnp.asarray(np.concatenate([r, v])), jnp.asarray(p))
    c = camera_attitude(jnp.asarray(-r), jnp.array([0.0, 0, 1]))
    sigma = 3.2e-4
    return nav, predict_los(nav, c, sigma**2 * jnp.eye(2)), sigma


def test_planar_first_angle_only_leaves_the_in_plane_block_as_the_joint_update():
    """``angles=1``: with no out-of-plane correlation, an exact (zero-innovation) out-of-plane
    angle changes only out-of-plane entries: the in-plane state and covariance are the joint
    update's."""
    nav, pred, sigma = _planar_prediction(7)
    z = pred.z + jnp.asarray([2e-4, 0.0])
    ref, _ = ekf_update(nav, z, pred)
    r1, v1, pk = los_update(
        nav.r, nav.v, pack(nav.p), pred.jacobian[:, :3], z - pred.z, sigma**2, angles=1
    )
    in_plane = [0, 1, 3, 4]
    np.testing.assert_allclose(np.asarray(r1), np.asarray(ref.r), rtol=1e-13, atol=1e-6)
    np.testing.assert_allclose(np.asarray(v1), np.asarray(ref.v), rtol=1e-13, atol=1e-12)
    p1, p_ref = np.asarray(unpack(pk)), np.asarray(ref.p)
    blk = np.ix_(in_plane, in_plane)
    np.testing.assert_allclose(p1[blk], p_ref[blk], rtol=1e-10, atol=1e-10 * np.abs(p_ref).max())


def test_planar_packing_carries_the_in_plane_entries_only_and_updates_them_identically():
    """``pack(p, PLANAR)`` (10 entries, the planar intercept's form): the in-plane update and
    propagation equal the full packed filter's bit for bit (the dropped out-of-plane entries
    enter the full one only as exact zeros), the out-of-plane entries read as 0."""
    nav, pred, sigma = _planar_prediction(11)
    innov = pred.z * 0.0 + jnp.asarray([2e-4, 0.0])
    h_r = pred.jacobian[:, :3]
    full = los_update(nav.r, nav.v, pack(nav.p), h_r, innov, sigma**2, angles=1)
    planar = los_update(nav.r, nav.v, pack(nav.p, PLANAR), h_r, innov, sigma**2, angles=1)
    assert len(planar[2].entries) == 10 and planar[2][2, 0] == 0.0
    in_plane = np.ix_([0, 1, 3, 4], [0, 1, 3, 4])
    for a, b in zip(full[:2], planar[:2]):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    pf, pp = (np.asarray(unpack(propagate_packed(x[2], 1.0, 1e-9))) for x in (full, planar))
    np.testing.assert_array_equal(pf[in_plane], pp[in_plane])
    assert np.all(pp[2] == 0.0) and np.all(pp[:, 5] == 0.0)


def test_rejected_image_and_certain_filter():
    rng = np.random.default_rng(3)
    r, v, p = _case(rng)
    h_r = jnp.asarray(rng.standard_normal((2, 3)) * 1e-9)
    innov = jnp.asarray([1e-4, -2e-4])
    r1, v1, pk = los_update(
        jnp.asarray(r), jnp.asarray(v), pack(jnp.asarray(p)), h_r, innov, 1e-7, valid=False
    )
    np.testing.assert_array_equal(np.asarray(r1), r)
    np.testing.assert_array_equal(np.asarray(v1), v)
    np.testing.assert_array_equal(np.asarray(unpack(pk)), p)
    # P = 0 and R = 0: S is the floor, the gain zero (as ekf_update)
    r2, v2, pk2 = los_update(
        jnp.asarray(r), jnp.asarray(v), pack(jnp.zeros((6, 6))), h_r, innov, 0.0
    )
    np.testing.assert_array_equal(np.asarray(r2), r)
    np.testing.assert_array_equal(np.asarray(unpack(pk2)), 0.0)


def test_long_run_covariance_stays_symmetric_positive_definite():
    """A 25 h run of 1 s updates and propagations (the scenario's rate, a 3-D closing geometry
    with large knowledge errors): the packed covariance stays positive definite and equal to
    the dense filter's."""
    r0 = np.array([-1e3, 9.36e8, 2e5])
    vel = np.array([0.0, -1.02e4, -2.0])
    p0 = np.diag([1e12, 1e10, 1e10, 1.0, 1.0, 1.0])  # 1000 km along, 100 km across, 1 m/s
    sigma, q, n = 3.2e-4, 1e-12, 91_000
    h = jnp.array([0.0, 0.0, 1.0])

    def step(state, k):
        r_hat, v_hat, pk, p = state
        r_true = jnp.asarray(r0) + jnp.asarray(vel) * k
        c = camera_attitude(-r_hat, h)
        nav = NavEstimate(jnp.concatenate([r_hat, v_hat]), p)
        pred = predict_los(nav, c, sigma**2 * jnp.eye(2))
        xc = c @ (-r_true)
        z = xc[:2] / xc[2]
        dense, _ = ekf_update(nav, z, pred)
        r1, v1, pk1 = los_update(r_hat, v_hat, pk, pred.jacobian[:, :3], z - pred.z, sigma**2)
        pk1 = propagate_packed(pk1, 1.0, q)
        p1 = propagate_covariance(dense.p, 1.0, q, 0.0)
        r1, v1 = r1 + v1, v1
        return (r1, v1, pk1, p1), None

    x0 = (
        jnp.asarray(r0 + [5e5, 5e4, -5e4]),
        jnp.asarray(vel + 0.5),
        pack(jnp.asarray(p0)),
        jnp.asarray(p0),
    )
    (r_hat, _, pk, p), _ = jax.jit(lambda x: jax.lax.scan(step, x, jnp.arange(1.0, n + 1.0)))(x0)
    packed, dense = np.asarray(unpack(pk)), np.asarray(p)
    assert np.all(np.linalg.eigvalsh(packed) > 0)
    scale = np.sqrt(np.outer(np.diag(dense), np.diag(dense)))
    assert np.abs((packed - dense) / scale).max() < 1e-6
    # the filter converged across the LOS (range stays unobservable from angles alone)
    assert np.sqrt(packed[0, 0]) < 1e6
