"""A run whose navigation is lost ends ``nav_lost``, counted in ``failed``."""

import jax.numpy as jnp
import numpy as np
from scipy import stats

import gnc_jax as gj
from gnc_jax.navigation.ekf import (
    NIS_BOUND_1DOF,
    NIS_BOUND_2DOF,
    navigation_lost,
    normalised_innovation_squared,
)
from gnc_jax.systems.impactor.system import ImpactorSystem


def test_nis_and_its_bound():
    assert abs(NIS_BOUND_2DOF - stats.chi2.ppf(0.999, 2)) < 1e-9
    assert abs(NIS_BOUND_1DOF - stats.chi2.ppf(0.999, 1)) < 1e-9
    rng = np.random.default_rng(1)
    for _ in range(20):
        a = rng.normal(size=(2, 2))
        s = a @ a.T + 0.1 * np.eye(2)
        nu = rng.normal(size=2)
        ref = nu @ np.linalg.solve(s, nu)
        assert abs(float(normalised_innovation_squared(jnp.asarray(nu), jnp.asarray(s))) - ref) < (
            1e-12 * max(ref, 1.0)
        )


def test_the_criterion_is_most_images_unused_or_outside():
    n = 100
    assert not navigation_lost(n, 50, 0)  # half unused: not yet "most"
    assert navigation_lost(n, 49, 0)
    assert not navigation_lost(n, 100, 50)
    assert navigation_lost(n, 100, 51)


def test_a_target_below_the_noise_ends_nav_lost():
    """The image front end with an exposure of 1 e- in a fully lit pixel (read noise 20 e-):
    nothing rises above the threshold, no frame is used, and every run is nav_lost (not ok)."""
    overrides = {
        **ImpactorSystem.test_overrides,
        "navigation.measurement": "image",
        "camera.signal_e": 1.0,
        # the smallest frame the front end allows: the same code paths, compiled quickly
        "camera.samples": 4,
        "camera.roi_px": 12,
        "camera.window_px": 7,
        "camera.label_iterations": 2,
        "camera.max_bin_log2": 10,
    }
    sc = gj.load_scenario("deep-impact-los", overrides)
    study = gj.run_study(sc, runs=2, seed=0, progress=False, n_devices=1)
    s = study.summary()
    assert np.all(study.status == gj.Status.nav_lost)
    assert s["failed"] == 2 and s["failed_by_status"] == {"nav_lost": 2}
    sim, _ = gj.build(sc)
    np.testing.assert_array_equal(study.outcomes["images_rejected"], sim.n_images)
