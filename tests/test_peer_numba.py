"""The numba peer (benchmarks/peers/numba_impactor.py) flies gnc_jax's impactor closed loop.

Fed gnc_jax's standard normals (``run_draws`` of each run's key), its outcomes must equal
gnc_jax's vmapped ``simulate`` run for run: miss to 1e-6 m, identical firings. The nominal
``deep-impact-los`` has no gravity, so an off-nominal approach (another direction, range,
image interval, control step, gain and retarget time, with the target's gravity and the solar
tide on) checks the transcription away from that one point. Drawing its own normals inside
the kernel, its outcome distributions must match gnc_jax's (two-sample tests).
"""

import pathlib
import sys

import numpy as np
import pytest

pytest.importorskip("numba")
stats = pytest.importorskip("scipy.stats")

import gnc_jax as gj  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from benchmarks.peers import numba_impactor as peer  # noqa: E402
from benchmarks.peers import numba_impactor_kernel as kernel  # noqa: E402

# A 2000 s approach from another direction, with gravity (a ~1.4 km body at 1.2 AU) and
# proportionally smaller errors; the gnc_jax outcomes differ from the nominal's (not one point).
OFF_NOMINAL = [
    "approach.position_km=[17640.0, 6860.0, -3136.0]",
    "approach.velocity_kmps=[-9.0, -3.5, 1.6]",
    "errors.delivery_position_km=2.0",
    "navigation.knowledge_position_km=[40.0, 2.0, 2.0]",
    "camera.image_interval_s=10.0",
    "guidance.dt_s=0.5",
    "guidance.los.k1=3.0",
    "guidance.retarget_tgo_s=500.0",
    "dynamics.mu_target_m3s2=2e9",
    "dynamics.sun_distance_au=1.2",
    "dynamics.sun_direction=[0.3, 0.8, -0.5]",
]
# Runs compared run for run: for the packaged scenario 300 in the default chunks, the program
# that tests/systems/impactor/test_simulation.py::test_paper_scale_deep_impact compiles.
RUNS = {"nominal": 300, "off-nominal": 20}
COMPARED = ("dv_mps", "burn_time_s", "fuel_kg", "nav_sigma_b_m", "los_error_rms_urad")


@pytest.fixture(scope="module", params=["nominal", "off-nominal"])
def case(request):
    """``(scenario, runs)``: the scenario and its runs compared run for run (RUNS)."""
    overrides = OFF_NOMINAL if request.param == "off-nominal" else None
    return gj.load_scenario("deep-impact-los", overrides=overrides), RUNS[request.param]


@pytest.fixture(scope="module")
def scenario(case):
    return case[0]


@pytest.fixture(scope="module")
def fed(case):
    """gnc_jax's outcomes of the case's runs, their normals, and the peer's outcomes fed them."""
    scenario, runs = case
    ref = gj.run_study(scenario, runs=runs, seed=3, chunk_size=runs, progress=False).outcomes
    sim, _ = gj.build(scenario)
    # Writable copies (numba types a read-only array, as numpy views of JAX arrays are, apart):
    # the rolled draws below are writable too, so one compilation of the kernel serves both.
    draws = tuple(np.array(a) for a in peer.gnc_jax_draws(sim, runs, seed=3))
    return ref, draws, peer.run_fed(scenario, *draws)


def test_fed_draws_reproduce_gnc_jax_run_for_run(fed):
    ref, _, got = fed
    np.testing.assert_array_equal(got["status"], ref["status"])
    np.testing.assert_array_equal(got["firings"], ref["firings"])
    for name in ("miss_m", "miss_t_m", "miss_r_m", "b_t_m", "b_r_m"):
        np.testing.assert_allclose(got[name], ref[name], rtol=0, atol=1e-6, err_msg=name)
    for name in COMPARED:
        np.testing.assert_allclose(got[name], ref[name], rtol=1e-9, atol=1e-12, err_msg=name)
    # The filter's position error is a difference of 1e7 m positions: 1e-9 relative to them.
    np.testing.assert_allclose(
        got["nav_position_error_m"], ref["nav_position_error_m"], rtol=0, atol=1e-3
    )
    # The runs exercise the law: several firings, burns after the retarget (Δv of m/s).
    assert ref["firings"].min() >= 2 and np.median(ref["dv_mps"]) > 1.0


def test_fed_draws_matter(scenario, fed):
    # Another run's draws give that run's outcome: the comparison above is not vacuous.
    _, draws, got = fed
    rolled = peer.run_fed(scenario, *(np.roll(a, 1, axis=0) for a in draws))
    np.testing.assert_array_equal(rolled["miss_m"], np.roll(got["miss_m"], 1))
    assert np.all(np.abs(rolled["miss_m"] - got["miss_m"]) > 1e-3)


def test_kernel_generator_draws_standard_normals():
    """The own-draws kernel's ziggurat (xoshiro256**) against the normal distribution: KS,
    the first four moments and the tail beyond the ziggurat's last layer (its slow path)."""
    x = kernel.normals(12345, 400_000)
    assert stats.kstest(x, "norm").pvalue > 1e-3
    n = x.size
    assert abs(x.mean()) < 5 / np.sqrt(n) and abs(x.var() - 1.0) < 5 * np.sqrt(2 / n)
    assert abs(stats.skew(x)) < 5 * np.sqrt(6 / n) and abs(stats.kurtosis(x)) < 5 * np.sqrt(24 / n)
    tail = 2 * stats.norm.sf(kernel.ZIGGURAT_R)  # 2.6e-4: about 100 draws
    count = np.count_nonzero(np.abs(x) > kernel.ZIGGURAT_R)
    assert abs(count - n * tail) < 5 * np.sqrt(n * tail)
    assert len(np.unique(x)) == n and not np.array_equal(x[:10], kernel.normals(12346, 10))


def test_own_draws_are_reproducible_per_run():
    scenario = gj.load_scenario("deep-impact-los", overrides=OFF_NOMINAL)
    a = peer.run_own(scenario, 6, seed=100)
    b = peer.run_own(scenario, 3, seed=103)  # runs 3..5 of the first call
    np.testing.assert_array_equal(a["miss_m"][3:], b["miss_m"])
    assert len(np.unique(a["miss_m"])) == 6


def _p_values(scenario, runs, chunk) -> dict:
    """p-values of the hypothesis that the peer's own draws and gnc_jax's give the same
    distributions of the outcomes (two-sample KS; chi-square on the firing counts)."""
    # In the run-for-run test's chunks (RUNS): the executable compiled for it serves again.
    ref = gj.run_study(scenario, runs=runs, seed=0, chunk_size=chunk, progress=False).outcomes
    got = peer.run_own(scenario, runs, seed=987_654)
    assert np.all(got["status"] == gj.Status.ok) and np.all(ref["status"] == gj.Status.ok)
    p_values = {
        name: stats.ks_2samp(got[name], ref[name]).pvalue
        for name in ("miss_m", "dv_mps", "miss_t_m", "miss_r_m", "nav_sigma_b_m")
    }
    # Firings: chi-square on the counts below, at and above the pooled mode.
    mode = np.bincount(np.concatenate([got["firings"], ref["firings"]])).argmax()
    bins = [-0.5, mode - 0.5, mode + 0.5, np.inf]
    table = np.array([np.histogram(x["firings"], bins)[0] for x in (got, ref)])
    p_values["firings"] = stats.chi2_contingency(table[:, table.sum(axis=0) > 0]).pvalue
    return p_values


# Six tests of one hypothesis (same distributions): 1 % for the family (Bonferroni).
ALPHA = 0.01 / 6


def test_own_draws_match_gnc_jax_statistically():
    """CI size: 300 runs of the off-nominal approach (2000 s, about 1 s of gnc_jax)."""
    p = _p_values(
        gj.load_scenario("deep-impact-los", overrides=OFF_NOMINAL), 300, RUNS["off-nominal"]
    )
    assert len(p) == 6 and all(v > ALPHA for v in p.values()), p


@pytest.mark.slow
def test_own_draws_match_gnc_jax_statistically_deep_impact(paper_scale):
    """The flagship scenario, 1000 runs each (2000 with --paper-scale).

    500 runs each failed once, at p = 0.0002 on miss_r, after the draw layout changed (burn
    draws from a per-run table): gnc_jax's runs 0-499 have a mean miss_r of +0.4 m against
    -2.9 m over runs 0-3999, while 1000, 2000 and 4000 runs agree with the peer (p >= 0.016 on
    every outcome) and with the previous layout (p = 0.56 on miss_r, 2000 runs each)."""
    runs = 2000 if paper_scale else 1000
    p = _p_values(gj.load_scenario("deep-impact-los"), runs, RUNS["nominal"])
    assert len(p) == 6 and all(v > ALPHA for v in p.values()), p
