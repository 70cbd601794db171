"""Closed-loop impactor simulation: devices and keys, the laws at work, paper-scale check.

Batching, chunking, failed-run accounting, gradients and recompilation are checked for every
system and law by tests/test_family.py.
"""

import jax.numpy as jnp
import numpy as np
import pytest
from short_impactor import CHUNK, SHORT

import gnc_jax as gj


@pytest.fixture(scope="module", params=["deep-impact-los", "deep-impact-predictive"])
def short_scenario(request):
    return gj.load_scenario(request.param, overrides=SHORT)


def test_the_law_corrects_the_delivery_error(short_scenario):
    study = gj.run_study(short_scenario, runs=20, seed=0, chunk_size=CHUNK, progress=False)
    s = study.summary()
    assert s["failed"] == 0
    # another seed draws other errors (same run count: the same compiled program)
    other = gj.run_study(short_scenario, runs=20, seed=1, chunk_size=CHUNK, progress=False)
    assert not np.allclose(other.outcomes["delivery_error_m"], study.outcomes["delivery_error_m"])
    # the noise front end's LOS errors are its 10 urad model; no frame is ever rejected
    assert np.all(np.abs(study.outcomes["los_error_rms_urad"] - 10.0) < 3.0)
    assert np.all(study.outcomes["images_rejected"] == 0)
    # unguided, the 1 km (1-sigma per axis) delivery error plus the 3.2 km retarget would miss
    # by kilometres; guided, the miss is tens of metres
    assert s["miss_rms_m"] < 200.0
    assert s["dv_mean_mps"] > 1.0


PERFECT = [
    f"errors.{name}=0.0"
    for name in ("image_processing_urad", "attitude_control_urad", "attitude_bias_urad",
                 "attitude_noise_urad", "accel_bias_ug", "accel_noise_ug", "burn_magnitude_pct")
]  # fmt: skip


def test_a_perfect_sensor_keeps_navigation(short_scenario):
    """With every error source at zero the filter assumes at least a 10 nrad angle noise
    (``packed_ekf.ANGLE_NOISE_FLOOR_RAD``): told 0 it collapsed onto rounding errors and read
    its own rounding as hundreds of sigma, so every run ended nav_lost. Predictive guidance
    then lands within a metre. The LOS law's tolerances, k sqrt(E^2+F^2), shrink with the
    navigation error to the one-step resolution floor; with both tolerances at that floor the
    engine toggled every few steps and a quarter of the runs ran out of propellant: the floor
    keeps the band k1/k2 wide."""
    sc = short_scenario.with_overrides(PERFECT)
    study = gj.run_study(sc, runs=20, seed=0, chunk_size=CHUNK, progress=False)  # same program
    status = study.outcomes["status"]
    assert np.all(status == gj.Status.ok), np.bincount(status)
    s = study.summary()
    assert s["miss_max_m"] < (1.0 if short_scenario.name == "deep-impact-predictive" else 50.0)
    assert s["dv_max_mps"] < 20.0 and s["firings_max"] <= 8


def test_a_burn_the_engine_cannot_fly_reads_no_convergence():
    """Predictive guidance solves each burn by Newton iterations; an engine too weak for the
    schedule (2 N for burns 100-450 s before impact) leaves the predicted miss kilometres from
    the aim point. Those runs missed by 3.5 km RMS and read ``ok``; they end
    ``no_convergence`` now, and the packaged engine's runs stay ``ok``."""
    sc = gj.load_scenario("deep-impact-predictive", overrides=SHORT)
    weak = gj.run_study(
        sc.with_overrides(["spacecraft.thrust_n=2"]),
        runs=20,
        seed=0,
        chunk_size=CHUNK,
        progress=False,
    )
    assert np.all(weak.outcomes["status"] == gj.Status.no_convergence)
    assert np.median(weak.outcomes["miss_m"]) > 1e3
    nominal = gj.run_study(sc, runs=20, seed=0, chunk_size=CHUNK, progress=False)
    assert np.all(nominal.outcomes["status"] == gj.Status.ok)


def test_a_miss_beyond_the_delivery_tolerance_reads_missed():
    """A run whose B-plane point lies farther from the aim point than ``guidance.miss_limit_km``
    reads ``missed`` (an engine too weak to steer, 0.001 N, missed Tempel 1 by 13-20 km and
    read ``ok``). The unguided short approach (its state at the start, coasted to the B-plane)
    misses the aim point by the delivery error plus the 3.2 km retarget: ``missed`` under a
    tolerance below that miss, ``ok`` above it."""
    import equinox as eqx

    from gnc_jax.systems.impactor.simulation import finish, start

    outcome = eqx.filter_jit(finish)
    key = gj.run_key(0, 0)
    sc = gj.load_scenario("deep-impact-los", overrides=SHORT)
    sim, law = gj.build(sc)
    state, draws = start(sim, law, key)
    used = jnp.asarray(sim.n_images, jnp.int32)  # every image navigated: not nav_lost
    state = state._replace(tally=state.tally._replace(images_used=used))
    miss_km = float(outcome(sim, law, key, draws, state).miss_m) / 1e3
    assert miss_km > 1.0
    for limit_km, status in ((0.5 * miss_km, gj.Status.missed), (2.0 * miss_km, gj.Status.ok)):
        sim, law = gj.build(sc.with_overrides([f"guidance.miss_limit_km={limit_km}"]))
        out = outcome(sim, law, key, draws, state)
        assert float(out.miss_m) / 1e3 == miss_km
        assert int(out.status) == status, gj.Status.name_of(int(out.status))


def test_an_image_interval_that_does_not_divide_the_arc_ends_the_loop_at_the_cutoff():
    # 3000 s images on the 7140 s to the cut-off: two full intervals and one of 1140 s, so the
    # loop ends at the cut-off, 60 s (612 km) before the B-plane, and not at 9000 s, past it.
    sc = gj.load_scenario("deep-impact-los", {"camera.image_interval_s": 3000.0})
    outcome, trace = gj.simulate_one(sc, 0)
    t = np.asarray(trace.t_s)
    np.testing.assert_array_equal(t, np.arange(7200.0 - 60.0))  # each 1 s step, once
    speed = np.linalg.norm(np.asarray(trace.v_mps)[-1])
    approach_s = -np.dot(trace.r_m[-1], trace.v_mps[-1]) / speed**2
    assert approach_s == pytest.approx(60.0, abs=2.0)  # still approaching the target
    assert int(outcome.status) == gj.Status.ok and int(outcome.images_rejected) == 0
    sim, _ = gj.build(sc)
    assert (sim.n_images, sim.steps_per_image, sim.steps_after_cutoff) == (3, 3000, 3000 - 1140)


@pytest.mark.slow
def test_paper_scale_deep_impact(paper_scale):
    """Seed 000 (reduced to 300 runs in CI; --paper-scale runs the paper's 2000)."""
    runs = 2000 if paper_scale else 300
    los_study = gj.run_study(gj.load_scenario("deep-impact-los"), runs=runs, seed=0)
    pred_study = gj.run_study(gj.load_scenario("deep-impact-predictive"), runs=runs, seed=0)
    los, pred = los_study.summary(), pred_study.summary()
    assert los["failed"] == 0 and pred["failed"] == 0
    assert los["miss_rms_m"] <= 150.0
    assert los["miss_max_m"] <= 400.0
    assert 3.0 <= los["dv_mean_mps"] <= 10.0
    assert los["firings_max"] <= 10
    assert pred["miss_rms_m"] > los["miss_rms_m"]
    # Tempel 1 (7.6 x 4.9 km, long axis along R) holds the (1, 3) km aim point: guided runs
    # hit, counted against the axis-aligned ellipse of the B-plane points directly
    for study, summary in ((los_study, los), (pred_study, pred)):
        o = study.outcomes
        inside = (o["b_t_m"] / 2450.0) ** 2 + (o["b_r_m"] / 3800.0) ** 2 < 1.0
        assert summary["hits"] == int(np.sum(inside))
    assert los["hit_probability"] >= 0.99


def test_hit_probability_counts_impacts_inside_the_target():
    """A hit is an impact point inside the target's disc (a sphere here;
    no target gravity), counted against the B-plane points directly, with scipy's Wilson
    interval."""
    from scipy import stats

    radius_km = 3.2  # the (1, 3) km aim point sits 3.16 km from the centre: both outcomes occur
    sc = gj.load_scenario(
        "deep-impact-los", overrides=SHORT + [f"target.semi_axes_km=[{radius_km}, 3.2, 3.2]"]
    )
    # the compiled program of test_the_law_corrects_the_delivery_error
    study = gj.run_study(sc, runs=20, seed=3, chunk_size=CHUNK, progress=False)
    s = study.summary()
    o = study.outcomes
    hits = int(np.sum(np.hypot(o["b_t_m"], o["b_r_m"]) < radius_km * 1e3))
    assert 0 < hits < 20 and s["failed"] == 0
    assert s["hits"] == hits and s["hit_probability"] == hits / 20
    ci = stats.binomtest(hits, 20).proportion_ci(method="wilson")
    np.testing.assert_allclose(s["hit_probability_ci95"], [ci.low, ci.high], atol=1e-12)


def test_tempel_1_shadow_holds_the_aim_point_that_a_3_km_sphere_misses():
    """deep-impact-los's target seen along its approach S: Tempel 1 (7.6 x 4.9 km; semi-axes
    2.45, 2.45, 3.8 km) casts the B-plane shadow whose inside is a hit, against brute force: the
    smallest x^T A x along each point's line parallel to S, sampled every metre. By hand, the
    (1, 3) km aim point lies at 0.889 of the way to the shadow's edge (long axis along R) and
    at sqrt(10) / 3 of a 3 km sphere's; points beyond the edge, though within 3.8 km of the
    centre, count as misses, and a point beyond the short semi-axis hits the sphere only."""
    import jax
    import jax.numpy as jnp

    from gnc_jax.geometry.silhouette import silhouette_ratio
    from gnc_jax.systems.impact import hit_statistics
    from gnc_jax.systems.impactor.simulation import capture_silhouette

    def ratio(scenario, points):
        shadow = capture_silhouette(gj.build(scenario)[0])  # focusing included
        return np.asarray(jax.vmap(silhouette_ratio, (0, None, None))(points, shadow, 1.0))

    scenario = gj.load_scenario("deep-impact-los")
    sim, _ = gj.build(scenario)
    c_bi, c_body = np.asarray(sim.context.c_bi), np.asarray(sim.target.c_bi)
    a_mat = c_body @ np.diag(1.0 / np.array([2450.0, 2450.0, 3800.0]) ** 2) @ c_body.T
    y = np.random.default_rng(7).uniform([-3000.0, -4500.0], [3000.0, 4500.0], (300, 2))
    s = np.linspace(-5000.0, 5000.0, 10001)
    x = (y @ c_bi[1:])[:, None, :] + s[None, :, None] * c_bi[0]
    brute = np.einsum("npi,ij,npj->np", x, a_mat, x).min(axis=1) <= 1.0
    got = ratio(scenario, jnp.asarray(y))
    np.testing.assert_array_equal(got < 1.0, brute)
    assert 0.2 < brute.mean() < 0.8  # both sides sampled

    aim, beyond_r, beyond_t = [1000.0, 3000.0], [1500.0, 3400.0], [2600.0, 0.0]
    points = jnp.asarray([aim, beyond_r, beyond_t, [0.0, -3700.0]])
    assert np.all(np.hypot(*np.asarray(points).T) < 3800.0)
    tempel = ratio(scenario, points)
    np.testing.assert_allclose(tempel[0], np.hypot(1.0 / 2.45, 3.0 / 3.8), rtol=1e-12)
    sphere = ratio(gj.load_scenario("deep-impact-los", ["target.semi_axes_km=[3, 3, 3]"]), points)
    np.testing.assert_allclose(sphere[0], np.sqrt(10.0) / 3.0, rtol=1e-12)
    hits = hit_statistics({"silhouette_ratio": tempel}, np.ones(4, bool))
    assert hits["hits"] == 2 and list(tempel < 1.0) == [True, False, False, True]
    assert list(sphere < 1.0) == [False, False, True, False]  # (2.6, 0) km: inside 3 km only


def test_an_aim_point_off_the_target_is_warned_about():
    """The final aim point (1, 3) km lies sqrt(10) = 3.162 km from the centre: inside Tempel 1's
    shadow and a 3.2 km sphere's (no gravity: no focusing), outside a 3.1 km sphere's, where a
    run that flies it exactly misses the body. Warned, not refused."""
    system = gj.get_system("impactor")

    def warned(radius_km=None):
        r = radius_km
        over = [] if r is None else [f"target.semi_axes_km=[{r}, {r}, {r}]"]
        found = system.warnings(gj.load_scenario("deep-impact-los", overrides=over).config)
        return [w for w in found if w.startswith("guidance.aim_final_km: (1, 3) km lies outside")]

    assert warned() == [] and warned(3.2) == []
    (text,) = warned(3.1)
    assert "1.02 times its edge's distance" in text  # 3.162 / 3.1


def test_image_update_equals_the_dense_joseph_ekf_with_rodrigues_attitudes():
    # The loop's image (camera rows, series rotations, two scalar updates on the packed
    # covariance, NIS from the sequence) against the textbook chain: Rodrigues rotations,
    # stacked attitude matrices, predict_los and the dense Joseph-form ekf_update, NIS from
    # the 2x2 innovation covariance. Three images in sequence on the paper's geometry.
    import jax
    import jax.numpy as jnp

    from gnc_jax.navigation.camera import camera_attitude, small_rotation
    from gnc_jax.navigation.ekf import (
        ekf_update,
        normalised_innovation_squared,
        predict_los,
    )
    from gnc_jax.systems.impactor.draws import initial_conditions
    from gnc_jax.systems.impactor.navigation import take_image

    scenario = gj.load_scenario("deep-impact-los")
    sim, _ = gj.build(scenario)
    err = sim.errors
    key = jax.random.key(5)
    truth, nav, draws = jax.jit(initial_conditions)(sim, key)
    bias = draws["attitude_bias_rad"]

    def dense(nav, w):
        c_cmd = camera_attitude(-nav.r, sim.context.c_bi[2])
        c_true = small_rotation(err.attitude_control_rad * w[2:5]) @ c_cmd
        c_est = small_rotation(bias + err.attitude_noise_rad * w[5:8]) @ c_true
        sigma2 = err.image_processing_rad**2 + err.attitude_noise_rad**2
        predicted = predict_los(nav, c_est, sigma2 * jnp.eye(2))
        xc = c_true @ (-truth.r)
        z = xc[:2] / xc[2] + err.image_processing_rad * w[:2]
        updated, innovation = ekf_update(nav, z, predicted)
        return updated, normalised_innovation_squared(innovation, predicted.s)

    image = jax.jit(lambda nav, w: take_image(sim, nav, truth.r, bias, w, key))
    ref_nav, got_nav = nav, nav
    for i in range(3):
        w = jax.random.normal(jax.random.fold_in(key, i), (8,))
        got_nav, meas, got_nis = image(got_nav, w)
        ref_nav, ref_nis = jax.jit(dense)(ref_nav, w)
        assert bool(meas.valid)
        np.testing.assert_allclose(got_nav.x, ref_nav.x, rtol=1e-12, atol=1e-6)
        scale = np.abs(np.asarray(ref_nav.p)).max()
        np.testing.assert_allclose(got_nav.p, ref_nav.p, rtol=1e-8, atol=1e-12 * scale)
        np.testing.assert_allclose(got_nis, ref_nis, rtol=1e-8)
    # the images moved the estimate and shrank the cross-range variances (the angles do not
    # observe the range)
    assert np.linalg.norm(np.asarray(got_nav.x[:3] - nav.x[:3])) > 1.0
    cross = lambda p: np.asarray(p)[1, 1] + np.asarray(p)[2, 2]  # noqa: E731
    assert cross(got_nav.p) < 0.1 * cross(nav.p)


def test_camera_misalignment_rotates_the_measured_los_only():
    """``errors.camera_misalignment_urad``: the image is taken through the camera frame rotated
    by the run's drawn misalignment (against scipy's rotation of the camera frame), while the
    filter's predicted angles, through the attitude it believes, do not see it."""
    import jax
    import jax.numpy as jnp
    from scipy.spatial.transform import Rotation

    from gnc_jax.navigation.camera import camera_attitude
    from gnc_jax.navigation.packed_ekf import pack
    from gnc_jax.systems.impactor.draws import camera_misalignment, initial_conditions
    from gnc_jax.systems.impactor.navigation import camera_attitudes, image_update

    quiet = [  # no other attitude or centroiding error: the misalignment alone moves the LOS
        "errors.image_processing_urad=0.0",
        "errors.attitude_control_urad=0.0",
        "errors.attitude_noise_urad=0.0",
        "errors.attitude_bias_urad=0.0",
    ]
    scenario = gj.load_scenario(
        "deep-impact-los", overrides=quiet + ["errors.camera_misalignment_urad=500.0"]
    )
    sim, _ = gj.build(scenario)
    key = jax.random.key(7)
    truth, nav, _ = initial_conditions(sim, key)
    m = np.asarray(camera_misalignment(sim, key))
    assert 50e-6 < np.linalg.norm(m) < 3e-3  # a 500 urad 1-sigma per axis draw
    w, zero = jnp.zeros(8), jnp.zeros(3)
    attitudes = camera_attitudes(sim, nav.r, zero, w, jnp.asarray(m))
    _, meas = image_update(sim, nav.r, nav.v, pack(nav.p), truth.r, attitudes, w[:2], key)
    c_cmd = np.asarray(camera_attitude(-nav.r, sim.context.c_bi[2]))
    los = -np.asarray(truth.r)
    seen = Rotation.from_rotvec(np.array(m)).as_matrix() @ c_cmd @ los
    np.testing.assert_allclose(meas.z, seen[:2] / seen[2], rtol=1e-9, atol=1e-15)
    believed = c_cmd @ los  # the filter's attitude: the misalignment is not in it
    np.testing.assert_allclose(np.stack(attitudes[1]), c_cmd, atol=1e-15)
    offset = np.asarray(meas.z) - believed[:2] / believed[2]
    # to first order the boresight moves by (m_y, -m_x): the LOS angles shift by that
    np.testing.assert_allclose(offset, [m[1], -m[0]], rtol=0.05, atol=1e-3 * np.linalg.norm(m))


def test_camera_misalignment_acts_as_an_unknown_attitude_bias(monkeypatch):
    """Run for run, a camera misaligned by -b flies as an attitude reference biased by b that
    the filter does not consider (both rotate every measured LOS against the attitude the
    filter believes), to second order in b: the misalignment drawn from the attitude bias's
    normals (its stream id patched), against the attitude-bias error model."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from gnc_jax.systems.impactor import draws, simulation

    sigma = 300e-6  # rad: misses of hundreds of metres, against tens without it
    unknown = SHORT + ["navigation.consider_attitude_bias=false", "errors.attitude_bias_urad=0.0"]
    base, law = gj.build(gj.load_scenario("deep-impact-los", overrides=unknown))
    # leaves of the built dtype (a weakly typed scalar would be another program to compile)
    as_leaf = lambda x: jnp.full_like(base.errors.attitude_bias_rad, x)  # noqa: E731
    biased = eqx.tree_at(lambda s: s.errors.attitude_bias_rad, base, as_leaf(sigma))
    mis = gj.build(
        gj.load_scenario(
            "deep-impact-los", overrides=unknown + ["errors.camera_misalignment_urad=1"]
        )
    )[0]
    mis = eqx.tree_at(lambda s: s.errors.camera_misalignment_rad, mis, as_leaf(-sigma))
    assert mis.camera_misaligned and not base.camera_misaligned
    keys = jax.vmap(lambda i: gj.run_key(0, i))(jnp.arange(8))
    run = jax.jit(jax.vmap(lambda s, k: simulation.simulate(s, law, k)[0], in_axes=(None, 0)))
    monkeypatch.setattr(draws, "_MISALIGNMENT", draws._ATT_BIAS)
    a, b, c = run(base, keys), run(biased, keys), run(mis, keys)
    np.testing.assert_array_equal(b.status, c.status)
    for name in ("miss_t_m", "miss_r_m", "nav_position_error_m", "dv_mps"):
        x, y, z = (np.asarray(getattr(o, name)) for o in (a, b, c))
        assert np.max(np.abs(z - y)) <= 1e-3 * np.max(np.abs(y - x)), name
    rms = lambda o: np.sqrt(np.mean(np.asarray(o.miss_m) ** 2))  # noqa: E731
    assert rms(c) > 3 * rms(a)
    # the runs' other draws come from their own streams
    for name in ("delivery_error_m", "knowledge_position_error_m", "accel_bias_mps2"):
        np.testing.assert_array_equal(getattr(a, name), getattr(c, name), err_msg=name)


def test_reverse_mode_through_the_checkpointed_loop_matches_forward_mode_and_differences():
    """The relaxed LOS objective's gradient in both gains: reverse mode (through the
    checkpointed image steps and, inside them, the checkpointed control steps) equals forward
    mode, and both match central differences."""
    import jax
    import jax.numpy as jnp
    from relaxed_gradient import relaxed_objective

    f, problem, theta = relaxed_objective(
        "deep-impact-los", "impactor", ["guidance.los.k1", "guidance.los.k2"]
    )
    reverse = np.asarray(jax.jit(jax.grad(f, 1))(problem.args_for("reverse"), theta))
    # One forward-mode program, (point, direction) pairs: the derivative along each gain at
    # theta, and the values at theta +- h along each gain (their tangents unused).
    h = 1e-5
    steps = np.concatenate([np.eye(2) * h, -np.eye(2) * h])  # +h e0, +h e1, -h e0, -h e1
    points = jnp.concatenate([jnp.tile(theta, (2, 1)), theta + jnp.asarray(steps)])
    directions = jnp.concatenate([jnp.eye(2), jnp.zeros((4, 2))])
    pushed = jax.vmap(
        lambda args, th, d: jax.jvp(lambda th: f(args, th), (th,), (d,)), in_axes=(None, 0, 0)
    )
    values, tangents = (np.asarray(a) for a in jax.jit(pushed)(problem.args, points, directions))
    forward = tangents[:2]
    np.testing.assert_allclose(reverse, forward, rtol=1e-8)
    fd = (values[2:4] - values[4:6]) / (2 * h)
    assert np.all(np.abs(fd) > 0)
    np.testing.assert_allclose(reverse, fd, rtol=1e-3)
