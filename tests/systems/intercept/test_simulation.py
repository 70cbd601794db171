"""Closed-loop seed 004 intercept: Table 3 ordering, the closed-form pulse-train cost, 3-D
geometry, and the paper-scale Monte Carlo (reduced in CI). Batching, chunking, failed runs,
gradients and recompilation: tests/test_family.py."""

import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.systems.intercept.build import initial_state
from gnc_jax.systems.intercept.params import parameters
from gnc_jax.systems.intercept.system import estimate_pulse_trains

# A 2000 s approach (20 400 km, 10 km off) with proportionally smaller errors: same code paths.
SHORT = [
    "approach.impactor_position_km=[1.3417501e8, 20400.0, 0.0]",
    "guidance.coast_s=60.0",
    "navigation.knowledge_position_km=[2.0, 0.2, 0.2]",
]


@pytest.fixture(scope="module", params=["bennu-apn", "bennu-apn-3d"])
def short_scenario(request):
    return gj.load_scenario(request.param, overrides=SHORT)


def test_guidance_removes_the_delivery_error(short_scenario):
    s = gj.run_study(short_scenario, runs=6, seed=0, progress=False).summary()
    # unguided the miss is 10 km; the impulsive minimum Δv is 10 km / 2000 s = 5 m/s
    assert s["failed"] == 0
    assert s["miss_max_m"] < 500.0
    assert 4.5 < s["dv_mean_mps"] < 10.0
    if short_scenario.name == "bennu-apn-3d":
        assert s["miss_r_std_m"] > 0.0  # out-of-plane errors: both B-plane components
    else:
        assert s["miss_r_std_m"] == 0.0  # planar: the miss is B_T only


def test_a_filter_that_trusts_its_angles_too_much_ends_nav_lost(short_scenario):
    """The filter's innovations are checked against their covariance as the impactor's are
    (``navigation.ekf.navigation_lost``). A consistent filter has about 0.1 % of its images
    beyond the 99.9 % bound; one that assumes 10 urad for a 320 urad sensor has nearly all of
    them there and every run ends ``nav_lost``. (Such runs read ``ok`` before the intercept
    had the check, at twice the Δv.)"""
    nominal = gj.run_study(short_scenario, runs=6, seed=0, progress=False)  # compiled above
    o = nominal.outcomes
    assert np.all(o["status"] == gj.Status.ok) and np.all(o["images_rejected"] == 0)
    n_images = gj.build(short_scenario)[0].n_images
    assert np.all(o["innovations_outside"] <= 0.01 * n_images)
    tight = short_scenario.with_overrides(["navigation.model_attitude_urad=10"])
    lost = gj.run_study(tight, runs=6, seed=0, progress=False)
    assert np.all(lost.outcomes["status"] == gj.Status.nav_lost)
    assert np.all(lost.outcomes["innovations_outside"] > 0.5 * n_images)
    assert lost.summary()["failed_by_status"] == {"nav_lost": 6}


def test_3d_geometry_is_the_planar_case_on_bennus_orbit():
    planar, _ = initial_state(parameters(gj.load_scenario("bennu-apn").config))
    y3, is_planar = initial_state(parameters(gj.load_scenario("bennu-apn-3d").config))
    assert not is_planar
    # Table 1: r = a (1 - e^2) / (1 + e cos nu), out of the ecliptic by the inclination
    a, e, nu = 1.12639 * 1.495978707e11, 0.20375, np.radians(101.70395)
    assert float(jnp.linalg.norm(y3.r_target)) == pytest.approx(
        a * (1 - e * e) / (1 + e * np.cos(nu)), rel=1e-12
    )
    h = np.cross(np.asarray(y3.r_target), np.asarray(y3.v_target))
    assert np.degrees(np.arccos(h[2] / np.linalg.norm(h))) == pytest.approx(6.03494, rel=1e-9)
    for a_, b_ in ((y3.r, planar.r), (y3.v, planar.v)):
        assert float(jnp.linalg.norm(a_)) == pytest.approx(float(jnp.linalg.norm(b_)), rel=1e-12)
    assert float(y3.r @ y3.v) == pytest.approx(float(planar.r @ planar.v), rel=1e-12)


def test_table3_error_free_ordering():
    """Seed 004 Table 3: variable N (N0 = 8, k = 2) against constant N = 3 and N = 8."""
    res = {}
    for name in ("bennu-apn-ideal", "bennu-pn3-ideal", "bennu-pn8-ideal"):
        out, _ = gj.simulate_one(gj.load_scenario(name), record=False)
        assert out.status == gj.Status.ok
        res[name] = out
    apn, pn3, pn8 = (res[n] for n in ("bennu-apn-ideal", "bennu-pn3-ideal", "bennu-pn8-ideal"))
    for out in (apn, pn3, pn8):
        assert out.miss_m <= 10.0
        # never below the impulsive minimum: 1004 km unguided miss / 91 800 s
        assert out.dv_mps > 10.9
    assert apn.firings < pn3.firings < pn8.firings
    assert apn.dv_mps < pn8.dv_mps and pn3.dv_mps < pn8.dv_mps
    # The paper's 27 % saving of the variable law over N = 3 is not reproduced: with the
    # thresholds derived from the engine both use the impulsive minimum plus ~8 %, and which
    # of the two is cheaper depends on the trigger hysteresis (next test).
    assert abs(apn.dv_mps - pn3.dv_mps) < 0.01 * pn3.dv_mps


@pytest.mark.parametrize("trigger_on", [0.75, 1.0, 2.0])  # x a_ref, a_off = a_ref / 2
def test_error_free_closed_loop_matches_the_pulse_train_closed_form(trigger_on):
    """Full heliocentric closed loop against ``pulse_train_estimate`` (straight-line model).

    The closed form says the variable law (N0 = 8, k = 2) is cheaper than constant N = 3 only
    when rho = a_on / a_off > 2.25: here rho = 1.5, 2 and 4.
    """
    over = [f"guidance.apn.trigger_on={trigger_on}", "guidance.apn.trigger_off=0.5"]
    sim, est = {}, {}
    for name in ("bennu-apn-ideal", "bennu-pn3-ideal", "bennu-pn8-ideal"):
        scenario = gj.load_scenario(name, overrides=over)
        sim[name], _ = gj.simulate_one(scenario, record=False)
        est[name] = estimate_pulse_trains(scenario)
    for name in ("bennu-apn-ideal", "bennu-pn3-ideal"):
        assert float(sim[name].dv_mps) == pytest.approx(est[name].dv_mps, abs=0.03)
        # the impulse bit ends each train below a_off, so the closed loop needs fewer trains
        assert 0.6 * est[name].trains <= int(sim[name].firings) <= est[name].trains
    var, n3 = "bennu-apn-ideal", "bennu-pn3-ideal"
    d_sim = float(sim[var].dv_mps - sim[n3].dv_mps)
    d_est = est[var].dv_mps - est[n3].dv_mps
    if abs(d_est) > 0.03:  # rho = 1.5 (N = 3 cheaper) and rho = 4 (variable cheaper)
        assert np.sign(d_sim) == np.sign(d_est)
        assert d_sim == pytest.approx(d_est, abs=0.02)
    # N = 8 trains run into the chatter zone: the closed form (no chatter) is a lower bound
    pn8 = est["bennu-pn8-ideal"]
    assert pn8.train_tgo_s[-1] < pn8.chatter_tgo_s
    assert float(sim["bennu-pn8-ideal"].dv_mps) > pn8.dv_mps + 1.0


@pytest.mark.slow
def test_paper_scale_monte_carlo(paper_scale):
    """Seed 004: miss RMS <= 150 m, Δv mean <= 20 m/s (paper: 83.4 m, 9.56 m/s).

    2000 runs with --paper-scale; 60 in CI (the RMS of 60 runs is within ~20 % of the 2000's).
    """
    runs = 2000 if paper_scale else 60
    s = gj.run_study(gj.load_scenario("bennu-apn"), runs=runs, seed=0, progress=False).summary()
    assert s["failed"] == 0
    assert s["miss_rms_m"] <= 150.0
    assert s["dv_mean_mps"] <= 20.0
    assert s["miss_max_m"] <= 600.0


@pytest.mark.parametrize("image_interval_s", [1.0, 3.0])
def test_packed_filter_and_draw_blocks_keep_the_per_run_statistics(image_interval_s):
    """Several images per draw block plus a remainder block (the short arc has 1940 images,
    not a multiple of DRAW_BLOCK), and a 3 s image interval (three guidance steps per image,
    the spare pointing draws): every run ok, the filter converges across the LOS and the
    miss is removed; run i is the same in a batch of 2 and of 5 (per-run keys and blocks)."""
    from gnc_jax.systems.intercept.draws import DRAW_BLOCK
    from gnc_jax.systems.intercept.simulation import simulate

    over = SHORT + [f"navigation.image_interval_s={image_interval_s}"]
    scenario = gj.load_scenario("bennu-apn", overrides=over)
    sim, law = gj.build(scenario)
    assert sim.n_images % DRAW_BLOCK != 0
    keys = [gj.run_key(0, i) for i in range(5)]
    import jax

    run = jax.jit(jax.vmap(lambda k: simulate(sim, law, k)[0]))
    five = run(jnp.stack(keys))
    two = run(jnp.stack(keys[:2]))
    np.testing.assert_array_equal(np.asarray(five.miss_m[:2]), np.asarray(two.miss_m))
    assert np.all(np.asarray(five.status) == gj.Status.ok)
    assert float(jnp.max(five.miss_m)) < 500.0
    # across the LOS the estimate converged (range itself is unobservable from angles alone)
    know = np.linalg.norm(np.asarray(five.knowledge_position_error_m), axis=1)
    assert np.all(np.asarray(five.nav_position_error_m) < know + 1e3)


def test_intercept_hit_probability_is_the_miss_against_the_target_radius():
    """For the intercept, a hit is a B-plane miss inside Bennu's radius."""
    import gnc_jax as gj

    sc = gj.load_scenario("bennu-apn-ideal")
    study = gj.run_study(sc, runs=1, progress=False)
    radius = sc.config["dynamics"]["target_radius_m"]
    o, s = study.outcomes, study.summary()
    np.testing.assert_allclose(o["silhouette_ratio"], o["miss_m"] / radius, rtol=1e-6)
    assert s["hits"] == int(np.sum(o["miss_m"] < radius)) == 1 and s["hit_probability"] == 1.0


def test_reverse_mode_through_the_checkpointed_loop_matches_forward_mode():
    """The relaxed intercept objective's gradient in the APN law's gains: reverse mode (through
    the checkpointed blocks of images and, inside them, the checkpointed image steps) equals
    forward mode, run for run the same relaxed flights."""
    import jax
    from relaxed_gradient import relaxed_objective

    f, problem, theta = relaxed_objective(
        "bennu-apn", "intercept", ["guidance.apn.n0", "guidance.apn.k"]
    )
    reverse = np.asarray(jax.jit(jax.grad(f, 1))(problem.args_for("reverse"), theta))
    forward = np.asarray(jax.jit(jax.jacfwd(f, 1))(problem.args, theta))
    assert np.all(np.isfinite(forward)) and np.all(forward != 0.0)
    np.testing.assert_allclose(reverse, forward, rtol=1e-8)


def test_a_run_out_of_its_domain_or_beyond_its_propellant_is_flagged():
    """The final coast and outcome of a loop state: a B-plane miss beyond the initial range is
    ``out_of_domain``, more fuel burned than ``spacecraft.propellant_kg`` is ``propellant``,
    and the unguided approach itself (10 km off) is ``ok`` under a delivery tolerance wider
    than that."""
    import equinox as eqx

    from gnc_jax.systems.intercept.simulation import finish, start

    scenario = gj.load_scenario(
        "bennu-apn",
        overrides=SHORT + ["navigation.model=perfect", "guidance.miss_limit_km=1e7"],
    )
    sim, law = gj.build(scenario)
    key = gj.run_key(0, 0)
    state, draws = start(sim, law, key)
    truth = state.truth
    range0 = float(jnp.linalg.norm(truth.r))
    side = jnp.cross(truth.v, jnp.array([0.0, 0.0, 1.0]))
    side = side / jnp.linalg.norm(side)
    propellant = scenario.config["spacecraft"]["propellant_kg"]
    cases = [
        (truth, gj.Status.ok),
        (truth._replace(r=truth.r + 1.5 * range0 * side), gj.Status.out_of_domain),
        (truth._replace(m=truth.m - 1.01 * propellant), gj.Status.propellant),
    ]
    outcome = eqx.filter_jit(finish)
    for flown, status in cases:
        out = outcome(sim, law, key, draws, state._replace(truth=flown))
        assert int(out.status) == status, gj.Status.name_of(int(out.status))
        assert (float(out.miss_m) > range0) == (status == gj.Status.out_of_domain)
        assert (float(out.fuel_kg) > propellant) == (status == gj.Status.propellant)


def test_a_miss_beyond_the_delivery_tolerance_reads_missed():
    """A run that ends farther from the target than ``guidance.miss_limit_km`` reads
    ``missed`` (an engine that never steers still reaches the B-plane, 1000 km off at Bennu,
    and read ``ok``): the unguided approach, 10 km off, is ``missed`` under a 5 km tolerance
    and ``ok`` under a 20 km one, the miss itself the same."""
    import equinox as eqx

    from gnc_jax.systems.intercept.simulation import finish, start

    outcome = eqx.filter_jit(finish)
    misses = {}
    for limit_km, status in ((5.0, gj.Status.missed), (20.0, gj.Status.ok)):
        scenario = gj.load_scenario(
            "bennu-apn",
            overrides=SHORT + ["navigation.model=perfect", f"guidance.miss_limit_km={limit_km}"],
        )
        sim, law = gj.build(scenario)
        key = gj.run_key(0, 0)
        state, draws = start(sim, law, key)
        out = outcome(sim, law, key, draws, state)
        misses[limit_km] = float(out.miss_m)
        assert 5e3 < misses[limit_km] < 20e3
        assert int(out.status) == status, gj.Status.name_of(int(out.status))
    assert misses[5.0] == misses[20.0]
