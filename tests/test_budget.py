"""The error budget (gnc_jax.budget) against closed forms: a toy system whose variance shares
are known exactly (tests/budget_toy.py), the routing of each source's draws checked on the draws
themselves, and the budget's own checks."""

import importlib
import json
import os
import pathlib
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax._random import DrawKey, normal, run_key, stream_key, stream_normal, uniform
from gnc_jax.budget import format_table
from gnc_jax.budget.plan import factors, layout
from gnc_jax.systems import base

RUNS = 4000


@pytest.fixture(scope="module")
def toy():
    """The toy system, registered for this module only (the family tests do not see it)."""
    import budget_toy

    base.register_system(budget_toy.ToyBudgetSystem)
    yield budget_toy
    base._REGISTRY.pop("toy-budget", None)


def _draws(seed, runs, source):
    """Source ``source``'s standard normal of each run, drawn independently of the budget
    (from each run's own key, vmapped over the runs)."""
    draw = jax.vmap(lambda i: stream_normal(run_key(seed, i), source, ()))
    return np.asarray(draw(jnp.arange(runs)))


# Twelve intervals are checked at once (3 sources x 4 methods): each at 1 - 0.05 / 12, so that
# the test as a whole holds at 95 % (Bonferroni).
LEVEL = 1 - 0.05 / 12


def test_linear_toy_shares_are_the_analytic_ones(toy):
    c = np.array([1.0, 2.0, 3.0])
    b = gj.budget(toy.toy_scenario(), runs=RUNS, seed=5, bootstrap=400, level=LEVEL)
    analytic = c**2 / np.sum(c**2)
    for s, share in zip(("s0", "s1", "s2"), analytic):
        for method in ("first_order", "total", "one_at_a_time", "linear"):
            r = b.share("y", s, method)
            assert r["share_lo"] <= share <= r["share_hi"], (s, method, r)
    # the linear method is exact: its response to source s is c_s w_s run for run
    w = [_draws(5, RUNS, i) for i in range(3)]
    for i, s in enumerate(("s0", "s1", "s2")):
        assert b.share("y", s, "linear")["variance"] == pytest.approx(
            c[i] ** 2 * np.mean(w[i] ** 2), rel=1e-12
        )
    # one at a time: var(c_s w_s) of the study's own draws
    assert b.share("y", "s0", "one_at_a_time")["variance"] == pytest.approx(np.var(w[0], ddof=1))
    assert b.checks["y"]["first_sum_le_1"] and b.checks["y"]["total_ge_first"]
    # the all-on design is the study, run for run
    study = gj.run_study(toy.toy_scenario(), runs=RUNS, seed=5)
    assert b.checks["y"]["all_on_variance"] == np.var(study.outcomes["y"], ddof=1)
    assert b.nominal == {"status": 0, "identical_runs": True, "y": 0.0}


def test_a_declared_reason_replaces_the_linear_method(toy, monkeypatch):
    """A system that declares its derivatives are no sensitivities (the impactor with the
    rendered image front end) gets no linear shares: the reason is the budget's
    ``linear_error``, printed in place of the column, and the linear pass is not run."""
    reason = "derivatives through this model are not sensitivities"
    monkeypatch.setattr(toy.ToyBudgetSystem, "linear_unavailable", lambda self, cfg: reason)
    ran = []
    engine = importlib.import_module("gnc_jax.budget.engine")  # gj.budget is the function
    monkeypatch.setattr(engine, "linear_responses", lambda *a, **k: ran.append(1))
    b = gj.budget(toy.toy_scenario(), runs=64, seed=5, methods=("oat", "linear"), bootstrap=20)
    assert b.linear_error == reason and not ran
    assert not [r for r in b.rows if r["method"] == "linear"]
    assert [r for r in b.rows if r["method"] == "one_at_a_time"]
    impactor = gj.get_system("impactor")
    rendered = gj.load_scenario("autonav-predictive").config
    assert "navigation.measurement = 'image'" in impactor.linear_unavailable(rendered)
    assert impactor.linear_unavailable(gj.load_scenario("deep-impact-los").config) is None


def test_product_term_is_reported_as_an_interaction(toy):
    # y = w0 + w1 w2: Var 2, S0 = 1/2, S1 = S2 = 0, ST1 = ST2 = 1/2, interactions 1/2
    b = gj.budget(
        toy.toy_scenario(c1=0.0, c2=0.0, p=1.0), runs=RUNS, seed=7, bootstrap=400, level=LEVEL
    )
    for s in ("s1", "s2"):
        first, total = b.share("y", s, "first_order"), b.share("y", s, "total")
        assert first["share_lo"] <= 0.0 <= first["share_hi"]
        assert total["share_lo"] <= 0.5 <= total["share_hi"]
        assert first["share_hi"] < total["share_lo"]
        # the nominal run does not see the product: linear and one-at-a-time shares are zero
        assert b.share("y", s, "linear")["share"] == 0.0
        assert b.share("y", s, "one_at_a_time")["share"] == 0.0
    c = b.checks["y"]
    assert c["interaction_lo"] <= 0.5 <= c["interaction_hi"] and c["interaction_lo"] > 0.2


def test_groups_and_inactive_sources(toy):
    sc = toy.toy_scenario(c0=0.0)
    facs, inactive = factors(sc.system, sc, groups=True)
    assert facs == {"s12": ("s1", "s2")} and inactive == ["s0"]
    b = gj.budget(sc, runs=64, seed=1, groups=True, methods=("sobol",), bootstrap=50)
    # one factor carries all the variance: S = ST = 1 within sampling error
    assert b.share("y", "s12", "first_order")["share"] == pytest.approx(1.0, abs=0.3)
    assert b.share("y", "s12", "total")["share"] == pytest.approx(1.0, abs=0.3)


def test_budget_does_not_depend_on_chunking_or_devices(toy):
    """Every design's per-run metrics, the linear responses and hence every index are the
    same, bit for bit, whatever the chunk size and the number of devices."""
    assert len(jax.devices()) >= 2  # the test session's host devices (gnc_jax._config)
    sc = toy.toy_scenario(p=0.5)
    runs = dict(runs=40, seed=3, bootstrap=50)
    ref = gj.budget(sc, chunk_size=40, n_devices=1, **runs)
    for chunk, devices in ((8, 1), (6, 2), (None, 2)):
        b = gj.budget(sc, chunk_size=chunk, n_devices=devices, **runs)
        assert b.samples.keys() == ref.samples.keys()
        for design, (values, ok) in ref.samples.items():
            np.testing.assert_array_equal(b.samples[design][0], values, err_msg=design)
            np.testing.assert_array_equal(b.samples[design][1], ok, err_msg=design)
        assert b.rows == ref.rows and b.nominal == ref.nominal


@pytest.mark.parametrize(
    "call, message",
    [
        (dict(runs=4), "runs: 4; allowed: an integer >= 8"),
        (dict(metrics=["z"]), "metrics: 'z'; allowed: y"),
        (dict(groups={"g": ("s9",)}), "groups.g: unknown source 's9'; allowed: s0, s1, s2"),
        (dict(methods=("mc",)), "methods: 'mc'; allowed: sobol, oat, linear"),
    ],
)
def test_bad_requests_are_refused_in_one_line(toy, call, message):
    with pytest.raises(gj.ScenarioError) as e:
        gj.budget(toy.toy_scenario(), **call)
    assert str(e.value) == message


@pytest.mark.parametrize(
    "args, message",
    [
        (["--runs", "2"], "runs: 2; allowed: an integer >= 8"),
        (["--runs", "x"], "--runs: 'x'; allowed: an integer"),
        (["--metrics", "z"], "metrics: 'z'; allowed: y"),
        (["--methods", "mc"], "methods: 'mc'; allowed: sobol, oat, linear"),
        (["--set", "coefficients.q=1"], "coefficients.q: unknown field"),
    ],
)
def test_cli_refuses_bad_requests_in_one_line(toy, capsys, args, message):
    from gnc_jax import cli

    toml = str(pathlib.Path(__file__).with_name("toy_budget.toml"))
    with pytest.raises(SystemExit) as e:
        sys.exit(cli.main(["budget", toml, *args]))
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def _impactor_key(from_b):
    sc = gj.load_scenario("deep-impact-los")
    facs, _ = factors(sc.system, sc)
    lay = layout(sc.system, facs)
    n = len(facs) + 1
    pick = (
        jnp.zeros(n, bool).at[list(facs).index(from_b)].set(True) if from_b else jnp.zeros(n, bool)
    )
    a, b = run_key(3, 17), run_key(4, 17)
    return DrawKey(a, b, pick, jnp.ones(n), lay), a, b


def test_pick_freeze_pair_shares_exactly_the_frozen_sources_draws():
    from gnc_jax.systems.impactor import draws

    key, a, b = _impactor_key("attitude_control")
    img, img_a, img_b = (draws.image_draws(k, 9) for k in (key, a, b))
    np.testing.assert_array_equal(img[2:5], img_b[2:5])  # camera pointing: from b
    np.testing.assert_array_equal(img[:2], img_a[:2])  # centroiding, attitude noise: from a
    np.testing.assert_array_equal(img[5:], img_a[5:])
    burns, burns_a, burns_b = (draws.burn_draws(k) for k in (key, a, b))
    np.testing.assert_array_equal(burns[:, 1:4], burns_b[:, 1:4])  # thrust pointing: from b
    np.testing.assert_array_equal(burns[:, 5:8], burns_b[:, 5:8])
    np.testing.assert_array_equal(burns[:, [0, 4]], burns_a[:, [0, 4]])
    np.testing.assert_array_equal(burns[:, 8:], burns_a[:, 8:])
    for stream in range(5):  # delivery, knowledge, biases: from a
        np.testing.assert_array_equal(stream_normal(key, stream), stream_normal(a, stream))
    # nothing routed: the study's draws, bit for bit
    plain, _, _ = _impactor_key(None)
    np.testing.assert_array_equal(draws.image_draws(plain, 9), img_a)
    np.testing.assert_array_equal(draws.burn_draws(plain), burns_a)


def test_routed_uniform_and_undeclared_draws():
    lay = (((1,), 0),)
    a, b = run_key(1, 2), run_key(2, 2)
    key = DrawKey(a, b, jnp.array([True, False]), jnp.array([0.5, 1.0]), lay)
    u = uniform(stream_key(key, 1), (4,), -1.0, 1.0)
    np.testing.assert_allclose(u, 0.5 * jax.random.uniform(stream_key(b, 1), (4,), minval=-1.0))
    with pytest.raises(ValueError, match=r"draw at stream path \(2,\): no declared error source"):
        normal(stream_key(key, 2), (3,))


def test_cli_budget_and_report(tmp_path):
    """``gnc-jax budget`` on the toy system registered through the plugin variable, then
    ``gnc-jax report`` of its directory: a figure per metric."""
    tests_dir = pathlib.Path(__file__).parent
    env = {**os.environ, "GNC_JAX_PLUGINS": "budget_toy", "GNC_JAX_HOST_DEVICES": "1"}
    env["PYTHONPATH"] = os.pathsep.join([str(tests_dir), env.get("PYTHONPATH", "")])
    out = tmp_path / "b"
    cmd = [sys.executable, "-m", "gnc_jax", "budget", str(tests_dir / "toy_budget.toml")]
    done = subprocess.run(
        cmd + ["--runs", "64", "--out", str(out)], env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert "first order" in done.stdout and "s2" in done.stdout
    saved = json.loads((out / "budget.json").read_text())
    assert saved["runs"] == 64 and set(saved["factors"]) == {"s0", "s1", "s2"}
    assert (out / "budget.parquet").exists()
    report = subprocess.run(
        [sys.executable, "-m", "gnc_jax", "report", str(out)], env=env, capture_output=True
    )
    assert report.returncode == 0, report.stderr
    assert (out / "budget_y.png").read_bytes()[:4] == b"\x89PNG"


def test_a_metric_without_enough_ok_runs_says_how_many():
    """A method needs 8 runs ok in all its designs: fewer is said with the count, not as a
    metric without variance (which is what the same value in every run reads)."""
    budget = dict(
        metrics=["y"],
        methods=["sobol", "oat"],
        factors={"s0": ["s0"]},
        counts=dict(runs=8, all_on_ok=4, sobol_ok=4, oat_ok=4),
        checks={},
        rows=[],
    )
    assert format_table(budget) == (
        "y: too few ok runs to share its variance (sobol: 4 < 8 ok runs; oat: 4 < 8 ok runs)"
    )
    row = dict(metric="y", source="s0", method="one_at_a_time", share=1.0, share_lo=0.9)
    budget.update(
        counts=dict(runs=8, all_on_ok=8, sobol_ok=5, oat_ok=8),
        checks={"y": {"all_on_variance": 2.0, "oat_sum": 1.0}},
        rows=[dict(row, share_hi=1.1, variance=2.0)],
    )
    lines = format_table(budget).splitlines()
    assert lines[0] == "y: variance 2" and lines[-1] == "  not estimated (sobol: 5 < 8 ok runs)"
    budget.update(counts=dict(runs=8, all_on_ok=8, sobol_ok=8, oat_ok=8))
    budget["checks"]["y"]["all_on_variance"] = 0.0
    assert format_table(budget) == ("y: no variance (the same in every run): nothing to share")


def test_a_budget_seed_out_of_range_is_refused_before_any_design(monkeypatch):
    from gnc_jax.budget import engine

    monkeypatch.setattr(engine, "run_study", lambda *a, **k: pytest.fail("ran"))
    with pytest.raises(gj.ScenarioError, match=r"seed: 4294967296; allowed: an integer in"):
        gj.budget(gj.load_scenario("deep-impact-los"), runs=8, seed=2**32)
