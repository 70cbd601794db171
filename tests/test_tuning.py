"""Gain tuning (gnc_jax.tuning, ``gnc-jax tune``), on the toy system of tests/toy_system.py.

The toy double-integrator intercept compiles in about a second, so every check here runs the
whole tuner (gradients, the optimiser, the evaluation, the files) at CI cost. Each compares
with something independent: central differences of the objective computed by a per-run loop
over scenarios rebuilt from overrides, a second run of the tuner, the run-index sets, a fresh
``gnc-jax run`` of the written file.

The tunings share their shapes (batches of 8 runs; training checks and held-out sets of 24, or
12 for the weighted objective), so each of the tuner's programs compiles once in this module.
"""

import dataclasses
import json
import os
import pathlib
import subprocess
import sys
import tracemalloc

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax import cli
from gnc_jax import tuning as tune_module
from gnc_jax.scenario import ScenarioError
from gnc_jax.tuning import (
    HELDOUT_MAX_RUNS,
    HELDOUT_OFFSET,
    Reparametrisation,
    heldout_indices,
    paired_interval,
    parse_objective,
    resolve_gains,
    train_indices,
    tune,
)

TOY = str(pathlib.Path(__file__).with_name("toy.toml"))
# a shorter, noisier engagement than the demo: a few hundred steps per run
FAST = {"geometry.range_m": 3000.0, "geometry.dispersion_m": 200.0, "navigation.noise_m": 5.0}


def toy(**extra):
    return gj.load_scenario(TOY, overrides={**FAST, **extra})


def per_run_objective(scenario, n, runs, seed, weight):
    """miss_rms + weight * dv_mean of runs ``runs`` flown one at a time by the scenario rebuilt
    with ``guidance.pn.n = n`` (the scenario path, not the tuner's leaves)."""
    s = scenario.with_overrides({"guidance.pn.n": n})
    miss, dv = [], []
    for i in runs:
        out, _ = gj.simulate_one(s, index=int(i), seed=seed, record=False)
        miss.append(float(out.miss_m))
        dv.append(float(out.dv_mps))
    return np.sqrt(np.mean(np.square(miss))) + weight * np.mean(dv)


@pytest.mark.parametrize("gradient", ["forward", "reverse"])
def test_objective_gradient_matches_central_differences_of_a_per_run_loop(gradient):
    scenario = toy()
    objective = parse_objective("miss_rms+0.5*dv_mean", scenario)
    (gain,) = resolve_gains(scenario, ["guidance.pn.n"])
    problem = tune_module.TuningProblem(scenario, [gain], objective, seed=3)
    idx, valid = problem.padded(train_indices(0, 6, 6))
    n0 = float(scenario["guidance.pn.n"])
    theta = jnp.asarray(problem.param.theta([n0]))
    f = lambda th: problem.smooth(problem.args, th, None, idx, valid)  # noqa: E731
    grad_fn = jax.jacfwd(f) if gradient == "forward" else jax.grad(f)
    d_theta = float(jax.jit(grad_fn)(theta)[0])
    # theta is log(n - lo): d/dn = d/dtheta / (n - lo)
    d_n = d_theta / (n0 - gain.lo)
    value = float(jax.jit(f)(theta))
    np.testing.assert_allclose(value, per_run_objective(scenario, n0, range(6), 3, 0.5), rtol=1e-9)
    h = 1e-4
    fd = (
        per_run_objective(scenario, n0 + h, range(6), 3, 0.5)
        - per_run_objective(scenario, n0 - h, range(6), 3, 0.5)
    ) / (2 * h)
    assert abs(fd) > 1e-6  # the objective depends on the gain
    np.testing.assert_allclose(d_n, fd, rtol=1e-4)


def test_identical_seeds_give_identical_tuned_gains_and_other_seeds_do_not():
    kw = dict(batch=8, steps=4, heldout_runs=0, learning_rate=0.2, check_runs=24)
    a = tune(toy(), "guidance.pn.n", "miss_rms", seed=5, **kw)
    b = tune(toy(), "guidance.pn.n", "miss_rms", seed=5, **kw)
    c = tune(toy(), "guidance.pn.n", "miss_rms", seed=6, **kw)
    assert a.tuned == b.tuned
    assert [h["objective"] for h in a.history] == [h["objective"] for h in b.history]
    assert a.history[-1]["gains"] != c.history[-1]["gains"]


def test_training_and_heldout_runs_never_overlap(monkeypatch):
    batch, steps = 6, 5
    trained = set()
    for s in range(steps):
        trained |= set(train_indices(s, batch, batch * steps).tolist())
    assert trained == set(range(batch * steps))  # a fresh batch each step, each run once
    assert not trained & set(heldout_indices(1000).tolist())
    assert heldout_indices(3)[0] == HELDOUT_OFFSET
    with pytest.raises(ScenarioError, match="train_runs"):
        tune(toy(), "guidance.pn.n", batch=4, steps=2, train_runs=HELDOUT_OFFSET + 1)
    # the last held-out index is the last whose key is its own: fold_in takes it modulo 2^32
    last = HELDOUT_OFFSET + HELDOUT_MAX_RUNS - 1
    key = lambda i: jax.random.key_data(gj.run_key(0, i)).tolist()  # noqa: E731
    assert last == 2**32 - 1 and key(jnp.asarray(last + 1)) == key(0)
    assert key(jnp.asarray(last, jnp.int64).astype(jnp.int32)) == key(last)  # padded's int32
    for name in ("heldout_runs", "eval_runs"):
        with pytest.raises(ScenarioError, match=f"^{name}: {HELDOUT_MAX_RUNS + 1}; allowed"):
            tune(toy(), "guidance.pn.n", batch=4, steps=2, max_hours=1e12,
                 **{name: HELDOUT_MAX_RUNS + 1})  # fmt: skip

    # the indices the tuner actually flies: spy on both index functions
    seen = {"train": set(), "heldout": set()}

    def spy(name, fn):
        def wrapped(*args):
            out = fn(*args)
            seen[name] |= set(np.asarray(out).tolist())
            return out

        return wrapped

    for module in (tune_module.optimisers, tune_module.evaluation):
        monkeypatch.setattr(module, "heldout_indices", spy("heldout", heldout_indices))
    monkeypatch.setattr(tune_module.optimisers, "train_indices", spy("train", train_indices))
    result = tune(toy(), "guidance.pn.n", "miss_rms", batch=8, steps=3, heldout_runs=24)
    assert seen["train"] == set(range(24))
    assert seen["heldout"] == set(range(HELDOUT_OFFSET, HELDOUT_OFFSET + 24))
    assert result.heldout["paired_runs"] == 24


def test_a_non_finite_gradient_is_taken_as_zero_and_flagged(monkeypatch):
    """Adam's update takes a non-finite gradient component as 0; the step says so in its
    record and its progress line instead of following it silently."""
    real = tune_module.TuningProblem.compiled

    def poisoned(self, kind, build_fn, *args):
        fn, compile_s = real(self, kind, build_fn, *args)
        if not kind.startswith("adam"):
            return fn, compile_s

        def step(*a):
            value, grad = fn(*a)
            return value, jnp.asarray(grad).at[0].set(jnp.nan)

        return step, compile_s

    monkeypatch.setattr(tune_module.TuningProblem, "compiled", poisoned)
    result = tune(toy(), "guidance.pn.n", "miss_rms", batch=8, steps=2, heldout_runs=0,
                  check_runs=0)  # fmt: skip
    assert [rec.get("nonfinite_gradient") for rec in result.history] == [1, 1]
    assert result.tuned == result.initial  # the one gain never moved
    line = tune_module.progress_line(result.history[0], result.names)
    assert "gradient: 1 non-finite component(s) taken as 0" in line


def test_heldout_table_is_the_hard_paired_evaluation():
    result = tune(
        toy(),
        "guidance.pn.n",
        "miss_rms+0.5*dv_mean",
        batch=8,
        steps=3,
        heldout_runs=12,
        check_runs=12,
    )
    rows = {r["metric"]: r for r in result.heldout["rows"]}
    for side, gains in (("initial", result.initial), ("tuned", result.tuned)):
        # the same held-out runs, flown one at a time by the scenario with that gain
        expected = per_run_objective(toy(), gains[0], heldout_indices(12), 0, 0.5)
        np.testing.assert_allclose(rows["objective"][side], expected, rtol=1e-9)
    r = rows["objective"]
    assert r["ci_low"] <= r["difference"] <= r["ci_high"]
    assert "miss_rms" in rows and "dv_mean" in rows


def test_paired_bootstrap_interval_matches_the_normal_interval_of_a_mean_difference():
    rng = np.random.default_rng(0)
    a = rng.normal(10.0, 1.0, 4000)
    b = a + rng.normal(0.3, 0.5, 4000)  # paired: the runs' common part cancels
    diff, lo, hi = paired_interval(lambda i: a[i].mean(), lambda i: b[i].mean(), 4000)
    d = b - a
    half = 1.96 * d.std() / np.sqrt(len(d))
    np.testing.assert_allclose(diff, d.mean(), rtol=1e-12)
    np.testing.assert_allclose([lo, hi], [d.mean() - half, d.mean() + half], atol=0.15 * half)


def test_paired_interval_draws_one_resample_at_a_time():
    a = np.arange(7.0)
    b = a**2
    stat_a, stat_b = (lambda i: a[i].mean()), (lambda i: b[i].mean())
    draws = np.random.default_rng(3).integers(0, 7, size=(200, 7))  # all resamples at once
    ref = np.quantile([stat_b(d) - stat_a(d) for d in draws], [0.025, 0.975])
    _, lo, hi = paired_interval(stat_a, stat_b, 7, resamples=200, seed=3)
    assert [lo, hi] == list(ref)
    # held-out sets of millions of runs: the indices of one resample in memory, not of all
    n = 2_000_000
    x = np.zeros(n)
    tracemalloc.start()
    paired_interval(lambda i: x[i].mean(), lambda i: x[i].mean(), n, resamples=40)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 4 * 8 * n  # all 40 resamples' indices are 40 * 8 * n bytes


def test_reparametrisation_keeps_k1_above_k2_and_inverts():
    scenario = gj.load_scenario("deep-impact-los")
    gains = resolve_gains(scenario, ["guidance.los.k1", "guidance.los.k2"])
    param = Reparametrisation.of(scenario, gains)
    np.testing.assert_allclose(param.theta([4.0, 1.0]), [np.log(3.0), 0.0], atol=1e-15)
    for theta in np.random.default_rng(1).normal(0.0, 1.5, (50, 2)):
        k1, k2 = np.asarray(param.gains(jnp.asarray(theta)))
        assert k1 > k2 > 0.0
        if k1 < 100.0:  # k1's upper bound clips
            np.testing.assert_allclose(param.theta([k1, k2]), theta, rtol=1e-9, atol=1e-9)
    # one side of the pair alone stays on its side of the fixed other
    (k2_only,) = resolve_gains(scenario, ["guidance.los.k2"])
    param = Reparametrisation.of(scenario, [k2_only])
    assert all(0 < float(param.gains(jnp.asarray([t]))[0]) < 4.0 for t in (-30.0, 0.0, 30.0))


def test_gradient_free_baseline_spends_the_same_runs():
    kw = dict(batch=8, steps=3, heldout_runs=0, seed=1)
    adam = tune(toy(), "guidance.pn.n", "miss_rms", **kw)
    es = tune(toy(), "guidance.pn.n", "miss_rms", method="es", population=2, **kw)
    assert [h["runs"] for h in es.history] == [h["runs"] for h in adam.history]
    assert es.history[-1]["gains"] != es.initial  # it moved
    cma = tune(toy(), "guidance.pn.n", "miss_rms", method="cma", population=2, **kw)
    assert [h["runs"] for h in cma.history] == [h["runs"] for h in es.history]
    # generation 0: the same start on the same common runs as the ES's centre
    assert cma.history[0]["objective"] == es.history[0]["objective"]
    assert cma.history[-1]["gains"] != cma.initial


def test_the_result_is_the_checked_point_with_the_lowest_hard_training_objective():
    r = tune(toy(), "guidance.pn.n", "miss_rms", batch=8, steps=4, heldout_runs=0, check_every=1,
             check_runs=24, learning_rate=0.3)  # fmt: skip
    checked = [(r.training_check["initial"], r.initial)]
    checked += [(h["check"], h["check_gains"]) for h in r.history]
    assert len(checked) == 5
    assert r.tuned == min(checked, key=lambda c: c[0])[1]
    # each check is the hard objective of those gains on training runs 0..23 (per-run loop)
    value, gains = checked[2]
    np.testing.assert_allclose(value, per_run_objective(toy(), gains[0], range(24), 0, 0.0))


def test_tuned_toml_round_trips_through_gnc_jax_run(tmp_path):
    """``gnc-jax tune`` in a fresh process writes tuned.toml; ``gnc-jax run`` flies it, and its
    runs equal a study of the scenario with the tuned gain set by override."""
    tests_dir = pathlib.Path(__file__).parent
    env = {**os.environ, "GNC_JAX_PLUGINS": "toy_system"}
    env["PYTHONPATH"] = os.pathsep.join([str(tests_dir), env.get("PYTHONPATH", "")])
    out = tmp_path / "tuned"
    sets = [x for k, v in FAST.items() for x in ("--set", f"{k}={v}")]
    argv = [sys.executable, "-m", "gnc_jax", "tune", TOY, "--params", "guidance.pn.n"]
    argv += ["--objective", "miss_rms", "--batch", "8", "--steps", "3", "--heldout", "24"]
    done = subprocess.run(
        argv + ["--out", str(out), *sets], env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("step ") >= 3 and "held-out" in done.stdout
    for name in ("tuned.toml", "training.json", "heldout.json"):
        assert (out / name).is_file()
    assert (out / "training.png").read_bytes()[:4] == b"\x89PNG"
    tuned = json.loads((out / "heldout.json").read_text())["tuned"][0]
    scenario = gj.load_scenario(out / "tuned.toml")
    assert scenario["guidance.pn.n"] == tuned

    assert (
        cli.main(["run", str(out / "tuned.toml"), "--runs", "6", "--out", str(tmp_path / "r")]) == 0
    )
    ran = json.loads((tmp_path / "r" / "summary.json").read_text())
    expected = gj.run_study(toy(**{"guidance.pn.n": tuned}), runs=6, progress=False).summary()
    np.testing.assert_allclose(ran["miss_rms_m"], expected["miss_rms_m"], rtol=1e-9)


BAD_TUNE = [
    (["--params", "guidance.pn.nn"], "guidance.pn.nn: not a tunable leaf of toy-intercept"),
    (["--params", "guidance.dt_s"], "guidance.dt_s: not a tunable leaf"),
    (["--params", "guidance.zem.k"], "guidance.zem.k: a gain of a law this scenario does not fly"),
    (["--params", "guidance.pn.n", "--objective", "miss"], "objective: 'miss'"),
    (["--params", "guidance.pn.n", "--objective", "chute_rms"], "objective: chute_rms needs"),
    (["--params", "guidance.pn.n", "--objective", "peak_load"], "peak_load needs an argument"),
    (["--params", "guidance.pn.n", "--set", "guidance.pn.n=0.5"], "at its lower bound"),
    (["--params", "guidance.pn.n", "--objective", "0*miss_rms"], "weighs every term 0"),
    (["--params", "guidance.pn.n", "--objective", "miss_rms+-1*dv_mean"], "weight -1"),
    (["--params", "guidance.pn.n", "--objective", "1e999*miss_rms"], "weight inf"),
    (["--params", "guidance.pn.n", "--objective", "hit_probability(0)"], "argument 0"),
    (["--params", "guidance.pn.n", "--objective", "miss_rms+hit_probability(-5)"], "argument -5"),
]


@pytest.mark.parametrize("args,message", BAD_TUNE)
def test_bad_tune_input_is_one_line_before_compilation(
    args, message, capsys, monkeypatch, tmp_path
):
    def no_compile(*a, **k):
        raise AssertionError("compiled despite bad input")

    monkeypatch.setattr(tune_module.problem, "batch_function", no_compile)
    code = cli.main(["tune", TOY, "--out", str(tmp_path), *args])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1
    assert message in err and "allowed" in err


@pytest.mark.parametrize(
    "kw,message",
    [
        (dict(sigma=0.0), "sigma: 0.0; allowed: a finite number > 0"),
        (dict(sigma=float("nan")), "sigma: nan"),
        (dict(learning_rate=-0.1), "learning_rate: -0.1; allowed: a finite number > 0"),
        (dict(sigma="0.1"), "sigma: '0.1'"),
        (dict(temperature=-1.0), "temperature: -1.0; allowed: a finite number > 0"),
        (dict(temperature=(0.1, 0.0)), "temperature: (0.1, 0.0)"),
    ],
)
def test_a_bad_step_is_refused_before_compilation(kw, message, monkeypatch):
    def no_compile(*a, **k):
        raise AssertionError("compiled despite bad input")

    monkeypatch.setattr(tune_module.problem, "batch_function", no_compile)
    with pytest.raises(ScenarioError) as e:
        tune(toy(), "guidance.pn.n", "miss_rms", method="es", **kw)
    assert message in str(e.value) and len(str(e.value).splitlines()) == 1


@pytest.mark.parametrize("option", ["--sigma", "--population", "--learning-rate"])
def test_a_bad_cli_step_is_one_line(option, capsys, tmp_path):
    with pytest.raises(SystemExit) as e:
        cli.main(["tune", TOY, "--out", str(tmp_path), "--params", "guidance.pn.n", option, "0"])
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and len(err.splitlines()) == 1
    assert f"{option}: '0'; allowed" in err


def test_the_cli_passes_the_gradient_free_step_and_population(monkeypatch, tmp_path):
    seen = {}

    def fake_tune(scenario, names, objective, **kw):
        seen.update(kw)
        raise ScenarioError("stop here; allowed: nothing")

    monkeypatch.setattr(tune_module, "tune", fake_tune)
    args = ["--params", "guidance.pn.n", "--method", "cma", "--sigma", "0.3"]
    code = cli.main(["tune", TOY, "--out", str(tmp_path), *args, "--population", "3"])
    assert code == 2
    assert (seen["method"], seen["sigma"], seen["population"]) == ("cma", 0.3, 3)


def test_an_interrupted_tune_keeps_the_steps_done(monkeypatch, capsys, tmp_path):
    """Ctrl-C during training: the records of the steps done go to training.json, marked
    interrupted, and the command exits 130 as an interrupted ``run``; before any step, the
    directory it created is removed."""
    records = [
        dict(step=s, objective=1.0 / (s + 1), gains=[3.0 + s], temperature=None, runs=4, wall_s=s)
        for s in range(2)
    ]

    def fake_tune(scenario, names, objective, callback=None, **kw):
        for rec in records:
            callback(rec)
        raise KeyboardInterrupt

    monkeypatch.setattr(tune_module, "tune", fake_tune)
    args = ["tune", TOY, "--params", "guidance.pn.n", "--steps", "5"]
    assert cli.main([*args, "--out", str(tmp_path / "t")]) == 130
    saved = json.loads((tmp_path / "t" / "training.json").read_text())
    assert saved == dict(interrupted=True, steps=5, history=records)
    err = capsys.readouterr().err
    assert "interrupted after 2 of 5 steps" in err and "gnc-jax: interrupted" in err
    records.clear()
    assert cli.main([*args, "--out", str(tmp_path / "none")]) == 130
    assert not (tmp_path / "none").exists()


def test_the_cli_names_each_knot_of_a_tuned_schedule(monkeypatch, capsys, tmp_path):
    """A schedule is tuned knot by knot: the progress lines and the result name each knot."""
    from gnc_jax.tuning import result as result_module

    def fake_tune(scenario, names, objective, **kw):
        gains = [4.0, 4.0, 4.0, 1.0, 1.0, 1.0]
        kw["callback"](dict(step=0, objective=1.0, gains=gains, wall_s=0.0))
        knots = [f"{n}[{j}]" for n in names for j in range(3)]
        return tune_module.TuneResult(
            scenario, scenario, knots, gains, gains, "miss_rms", "adam", 0, 4, 1, [], None,
            0.0, 0.0,
        )  # fmt: skip

    monkeypatch.setattr(tune_module, "tune", fake_tune)
    monkeypatch.setattr(result_module, "plot_training", lambda *a: None)
    params = "guidance.los.k1_schedule,guidance.los.k2_schedule"
    args = ["--params", params, "--set", "guidance.los.schedule_tgo_s=[0,1200,7200]"]
    assert cli.main(["tune", "deep-impact-los", "--out", str(tmp_path), *args]) == 0
    out = capsys.readouterr().out
    assert "k1_schedule[0]=4 k1_schedule[1]=4 k1_schedule[2]=4 k2_schedule[0]=1" in out
    assert "guidance.los.k2_schedule[2]: 1 -> 1" in out


@pytest.mark.parametrize("max_failed,code", [(None, 3), ("0.5", 0)])
def test_a_tune_whose_tuned_gains_fail_held_out_runs_exits_3(
    max_failed, code, monkeypatch, capsys, tmp_path
):
    """Exit 3 when more than ``--max-failed`` of the tuned gains' held-out runs failed (as
    ``run``), naming both sides' failures; the results are written either way."""
    from gnc_jax.tuning import result as result_module

    def fake_tune(scenario, names, objective, **kw):
        heldout = dict(
            runs=10, paired_runs=6, failed={"initial": 1, "tuned": 4}, confidence=0.95,
            first_index=HELDOUT_OFFSET, rows=[],
        )  # fmt: skip
        return tune_module.TuneResult(
            scenario, scenario, names, [3.0], [3.5], "miss_rms", "adam", 0, 4, 1, [], heldout,
            0.0, 0.0,
        )  # fmt: skip

    monkeypatch.setattr(tune_module, "tune", fake_tune)
    monkeypatch.setattr(result_module, "plot_training", lambda *a: None)
    limit = [] if max_failed is None else ["--max-failed", max_failed]
    got = cli.main(["tune", TOY, "--out", str(tmp_path), "--params", "guidance.pn.n", *limit])
    err = capsys.readouterr().err.strip()
    assert got == code and (tmp_path / "tuned.toml").exists()
    if code:
        assert err == (
            "gnc-jax: 4 of 10 held-out runs failed with the tuned gains (1 with the initial "
            "gains), more than --max-failed 0.01"
        )


def test_a_tune_over_max_hours_is_refused_in_one_line_before_compilation(
    monkeypatch, capsys, tmp_path
):
    """The cost of every call the tuner makes, counted as its loops make them (the monitor's
    checks after steps 2, 5, 8, 9 and the start; evaluations at 0, 4, 8, 9), and a tuning
    over ``--max-hours`` refused before anything is compiled."""
    from gnc_jax.backend import select
    from gnc_jax.tuning import cost

    def no_compile(*a, **k):
        raise AssertionError("compiled despite a runaway cost")

    sizes = dict(
        batch=8, steps=10, population=2, train_runs=80, check_runs=5, check_every=3,
        eval_every=4, eval_runs=7, heldout_runs=11,
    )  # fmt: skip
    scenario = gj.load_scenario("deep-impact-los")
    a, b = cost.FORWARD_COST
    estimate, _ = cost.tune_cost(scenario, select("cpu"), "adam", "forward", 2, **sizes)
    assert estimate.runs == 10 * 8 * (a + 2 * b) + 5 * 5 + 4 * 7 + 2 * 11
    estimate, _ = cost.tune_cost(scenario, select("cpu"), "es", "auto", 2, **sizes)
    assert estimate.runs == 10 * 5 * 2 + 5 * 5 + 4 * 7 + 2 * 11
    monkeypatch.setattr(tune_module.problem, "batch_function", no_compile)
    args = ["--params", "guidance.los.k1", "--heldout", "1000000", "--max-hours", "0.01"]
    code = cli.main(["tune", "deep-impact-los", "--out", str(tmp_path / "t"), *args])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and not (tmp_path / "t").exists()
    assert "cost: tune of 40 steps x 64 runs x " in err and "2 x 1000000 held-out runs" in err
    assert "allowed: at most 0.01 h" in err
    with pytest.raises(ScenarioError, match="max_hours: 0; allowed: a finite number > 0"):
        tune(toy(), "guidance.pn.n", max_hours=0)


def test_an_exponents_sign_is_not_a_term_separator_and_the_article_fits_the_system():
    from gnc_jax.tuning.objectives import _check_fields

    objective = parse_objective("1e+3*miss_rms+2E+0*dv_mean+hit_probability(1e+2)", toy())
    assert objective.terms == ((1000.0, "miss_rms", None), (2.0, "dv_mean", None),
                               (1.0, "hit_probability", 100.0))  # fmt: skip
    with pytest.raises(ScenarioError, match="which an impactor run does not have"):
        _check_fields(parse_objective("chute_rms", toy()), ("miss_m",), "impactor")


def test_a_non_tunable_law_field_names_the_tunable_ones():
    with pytest.raises(ScenarioError) as e:
        resolve_gains(gj.load_scenario("deep-impact-los"), ["guidance.los.temperature"])
    assert "guidance.los.k1, guidance.los.k2" in str(e.value)


@pytest.mark.parametrize("name", ["phoenix-midcourse", "deep-impact-predictive"])
def test_a_scenario_whose_law_has_no_tunable_gain_says_so(name):
    with pytest.raises(ScenarioError) as e:
        resolve_gains(gj.load_scenario(name), ["guidance.los.k1"])
    assert f"scenario {name} (" in str(e.value) and "has no tunable gain; allowed: " in str(e.value)


def test_built_in_terms_match_numpy_and_their_relaxations_tend_to_them():
    from typing import NamedTuple

    class Out(NamedTuple):
        status: np.ndarray
        miss_m: np.ndarray
        dv_mps: np.ndarray
        b_t_m: np.ndarray
        b_r_m: np.ndarray
        downrange_err_km: np.ndarray
        crossrange_err_km: np.ndarray
        load_peak_g: np.ndarray

    rng = np.random.default_rng(3)
    n = 400
    out = Out(
        np.zeros(n, int),
        *(np.abs(rng.normal(1.0, 0.5, (7, n))) * [[80], [8], [60], [60], [1], [1], [5]]),
    )
    w = (rng.uniform(size=n) > 0.1).astype(float)  # failed runs weigh 0
    k = w > 0
    spec = "miss_rms+2*dv_mean+3*hit_probability(70)+chute_rms+4*peak_load(6)"
    objective = parse_objective(spec, toy())
    hit = np.hypot(out.b_t_m, out.b_r_m)[k] <= 70.0  # impactor: distance from the centre
    expected = {
        "miss_rms": np.sqrt(np.mean(out.miss_m[k] ** 2)),
        "dv_mean": np.mean(out.dv_mps[k]),
        "hit_probability(70)": 1.0 - np.mean(hit),
        "chute_rms": np.sqrt(np.mean(out.downrange_err_km[k] ** 2 + out.crossrange_err_km[k] ** 2)),
        "peak_load(6)": np.mean(np.maximum(out.load_peak_g[k] - 6.0, 0.0)),
    }
    got = objective.term_values(out, w)
    for name, value in expected.items():
        np.testing.assert_allclose(got[name], value, rtol=1e-12, err_msg=name)
    total = sum(wt * expected[t] for wt, t in zip([1, 2, 3, 1, 4], expected, strict=True))
    np.testing.assert_allclose(float(objective.value(out, w)), total, rtol=1e-12)
    smooth = [abs(float(objective.value(out, w, t)) - total) for t in (1e-1, 1e-2, 1e-4)]
    assert smooth[0] > smooth[1] > smooth[2] and smooth[2] < 1e-2


def test_hit_probability_without_a_radius_counts_what_the_study_counts():
    """Given no radius, hit_probability is 1 - the study's P(hit): B-plane points inside the
    target's silhouette. deep-impact-los's Tempel 1 (semi-axes 2.45, 2.45, 3.8 km, the long
    axis along R) holds most points about the (1, 3) km aim point, 3.16 km from the centre and
    so beyond the smallest semi-axis; counted against the axis-aligned ellipse directly."""
    from typing import NamedTuple

    from gnc_jax.geometry.silhouette import silhouette_ratio
    from gnc_jax.systems.impact import hit_statistics
    from gnc_jax.systems.impactor.simulation import capture_silhouette
    from gnc_jax.tuning.objectives import _check_fields

    class Out(NamedTuple):
        status: np.ndarray
        miss_m: np.ndarray
        b_t_m: np.ndarray
        b_r_m: np.ndarray
        silhouette_ratio: np.ndarray

    scenario = gj.load_scenario("deep-impact-los")
    shadow = capture_silhouette(gj.build(scenario)[0])
    rng = np.random.default_rng(5)
    y = np.array([1000.0, 3000.0]) + rng.normal(0.0, 400.0, (400, 2))
    ratio = np.asarray(jax.vmap(silhouette_ratio, (0, None, None))(jnp.asarray(y), shadow, 1.0))
    w = (rng.uniform(size=400) > 0.1).astype(float)  # failed runs weigh 0
    k = w > 0
    out = Out(np.where(k, 0, 6), np.hypot(y[:, 0] - 1e3, y[:, 1] - 3e3), y[:, 0], y[:, 1], ratio)
    inside = (y[:, 0] / 2450.0) ** 2 + (y[:, 1] / 3800.0) ** 2 < 1.0
    assert 0.5 < inside[k].mean() < 1.0  # both outcomes occur

    objective = parse_objective("hit_probability", scenario)
    assert objective.terms == ((1.0, "hit_probability", None),)
    got = objective.term_values(out, w)["hit_probability"]
    np.testing.assert_allclose(got, 1.0 - inside[k].mean(), rtol=1e-12)
    assert got == 1.0 - hit_statistics({"silhouette_ratio": ratio}, k)["hit_probability"]
    smooth = [abs(float(objective.value(out, w, t)) - got) for t in (1e-1, 1e-2, 1e-4)]
    assert smooth[0] > smooth[1] > smooth[2] and smooth[2] < 1e-2
    # a radius is a disc about the target's centre, whatever the shape
    disc = parse_objective("hit_probability(3000)", scenario).term_values(out, w)
    np.testing.assert_allclose(
        disc["hit_probability(3000)"], 1.0 - np.mean(np.hypot(y[:, 0], y[:, 1])[k] <= 3000.0)
    )
    # an outcome without a silhouette (a capsule's) is refused, naming the field it needs
    with pytest.raises(ScenarioError, match="hit_probability needs the outcome 'silhouette_ratio'"):
        _check_fields(objective, ("status", "downrange_err_km"), "capsule")


def test_a_batch_without_an_ok_run_is_nan_and_never_the_selected_point(monkeypatch):
    """No run counts (every weight 0): each built-in term, and so the objective, is NaN, not
    the best possible 0; the training check then keeps the lowest finite checked point."""
    from typing import NamedTuple

    from gnc_jax.tuning import tuner

    class Out(NamedTuple):
        status: np.ndarray
        miss_m: np.ndarray
        dv_mps: np.ndarray

    out = Out(np.full(4, 6), np.full(4, 50.0), np.full(4, 8.0))  # 6: propellant
    objective = parse_objective("miss_rms+10*dv_mean+hit_probability(70)", toy())
    for t in (None, 0.05):
        assert np.isnan(float(objective.value(out, np.zeros(4), t)))
    assert all(np.isnan(v) for v in objective.term_values(out, np.zeros(4)).values())
    monkeypatch.setattr(tuner, "_hard_scored", lambda *a: (float("nan"), 4))  # the start: no ok run
    history = [
        dict(step=0, check=float("nan"), check_failed=4, check_gains=[9.0]),
        dict(step=1, check=5.0, check_failed=0, check_gains=[2.0]),
    ]
    check, gains = tuner._training_check(None, [4.0], np.arange(4), history)
    assert gains == [2.0] and check["selected_step"] == 1


def test_a_gain_that_fails_more_runs_never_ranks_better(monkeypatch):
    """An objective over the ok runs falls when a gain turns the worst runs into failures: the
    training check and the gradient-free tuners rank fewer failed runs first, then the
    objective (on the same runs)."""
    from gnc_jax.tuning import tuner
    from gnc_jax.tuning.evaluation import lexicographic_scores, ranking_key

    monkeypatch.setattr(tuner, "_hard_scored", lambda *a: (10.0, 0))  # the start
    history = [
        dict(step=0, check=5.0, check_failed=2, check_gains=[9.0]),  # lower, but 2 runs failed
        dict(step=1, check=8.0, check_failed=0, check_gains=[3.0]),
        dict(step=2, check=9.0, check_failed=0, check_gains=[2.0]),
    ]
    check, gains = tuner._training_check(None, [4.0], np.arange(16), history)
    assert gains == [3.0] and check["selected_step"] == 1 and check["failed"]["tuned"] == 0
    # a population: its scores order the members as (failed, objective) does, and equal the
    # objectives where every member fails as many runs
    rng = np.random.default_rng(3)
    values = rng.normal(100.0, 30.0, 40)
    values[[4, 17]] = np.nan  # no ok run
    failed = rng.integers(0, 3, 40)
    failed[[4, 17]] = 32
    scores = lexicographic_scores(values, failed)
    finite = np.isfinite(values)
    by_key = sorted(np.flatnonzero(finite), key=lambda i: ranking_key(values[i], failed[i]))
    assert list(np.argsort(scores[finite], kind="stable")) == [
        list(np.flatnonzero(finite)).index(i) for i in by_key
    ]
    # a member with no ok run ranks after every other, at a finite score the ES can weigh
    assert np.isfinite(scores).all() and scores[~finite].min() > scores[finite].max()
    np.testing.assert_array_equal(
        lexicographic_scores(values[finite], np.full(38, 2)), values[finite]
    )


def test_a_held_out_record_that_fails_more_runs_never_reaches_the_target(monkeypatch):
    """The ``eval_every`` held-out records carry their failed runs, and ``runs_to_reach``
    ranks them as the training check does: a lower objective with more failed runs does not
    reach a target, fewer failed runs do; a grid's ``hard_scores`` hold both numbers."""
    from gnc_jax.tuning import optimisers

    scores = iter([(5.0, 2), (8.0, 0), (7.0, 1)])
    monkeypatch.setattr(optimisers, "_hard_scored", lambda *a: next(scores))

    class Param:
        def gains(self, theta):
            return theta

    problem = type("P", (), {"param": Param()})()
    monitor = dict(check_runs=0, check_every=0, eval_every=1, eval_runs=16)
    history = []
    for s in range(3):
        rec = dict(step=s, runs=8 * (s + 1), wall_s=float(s + 1))
        optimisers._monitor(problem, rec, np.array([1.0]), s, 3, monitor)
        history.append(rec)
    assert [(h["heldout"], h["heldout_failed"]) for h in history] == [(5.0, 2), (8.0, 0), (7.0, 1)]
    assert "held-out 5 (2 failed)" in optimisers.progress_line(
        dict(history[0], objective=1.0, gains=[1.0]), ["k"]
    )
    result = tune_module.TuneResult(
        None, None, ["k"], [1.0], [1.0], "miss_rms", "adam", 0, 8, 3, history, None, 0.0, 0.0
    )
    # target 6 with no failed run: 5.0 (2 failed) and 7.0 (1 failed) rank worse, 8.0 too
    assert result.runs_to_reach(6.0) is None
    assert result.runs_to_reach(8.0) == (16, 2.0)
    # a target record that failed one run: 5.0 with 2 failed still does not reach it
    assert result.runs_to_reach({"heldout": 6.0, "heldout_failed": 1}) == (16, 2.0)
    assert result.runs_to_reach(4.0, failed=2) == (16, 2.0)  # fewer failed runs rank first
    assert result.runs_to_reach(5.0, failed=2) == (8, 1.0)
    # hard_scores: each gain's (objective, failed runs) on the held-out runs
    values = tune_module.hard_scores(toy(), ["guidance.pn.n"], "miss_rms", [[3.0], [4.0]], 8)
    assert [f for _, f in values] == [0, 0]
    assert [v for v, _ in values] == tune_module.hard_objectives(
        toy(), ["guidance.pn.n"], "miss_rms", [[3.0], [4.0]], 8
    )


def _toy_outcomes(status, miss_m):
    from toy_system import ToyOutcome

    n = len(status)
    return ToyOutcome(np.asarray(status), np.asarray(miss_m, float), np.ones(n), np.ones(n))


def test_the_failed_term_is_the_fraction_of_the_runs_not_ok(monkeypatch):
    """``failed`` counts the runs of the batch (not its padding) that did not end ``ok`` or
    have a non-finite outcome, hard and smooth alike; the other terms stay over the ok runs."""
    scenario = toy()
    objective = parse_objective("miss_rms+100*failed", scenario)
    (gain,) = resolve_gains(scenario, ["guidance.pn.n"])
    problem = tune_module.TuningProblem(scenario, [gain], objective, seed=0)
    ok, time_out = int(gj.Status.ok), int(gj.Status.time_out)
    # runs 0..5 real (one time_out, one ok with a NaN miss), 6..7 padding (one time_out)
    status = [ok, time_out, ok, ok, ok, ok, time_out, ok]
    miss = [3.0, 900.0, 4.0, np.nan, 1.0, 2.0, 900.0, 3.0]
    out = _toy_outcomes(status, miss)
    monkeypatch.setattr(problem, "fn", lambda *a: out)  # the batch's outcomes, by hand
    idx, valid = problem.padded(np.arange(6), size=8)
    counted_miss = np.array([3.0, 4.0, 1.0, 2.0])  # the real runs that end ok, finite
    expected = np.sqrt(np.mean(counted_miss**2)) + 100.0 * 2.0 / 6.0
    value, _ = problem.hard(problem.args, np.array([3.0]), idx, valid)
    np.testing.assert_allclose(float(value), expected, rtol=1e-12)
    theta = jnp.asarray(problem.param.theta([3.0]))
    smooth = problem.smooth(problem.args, theta, None, idx, valid)
    np.testing.assert_allclose(float(smooth), expected, rtol=1e-12)
    # without a runs mask every run is the batch's: 3 of 8 fail
    terms = objective.term_values(out, np.asarray(problem.weights(out, jnp.ones(8))))
    assert terms["failed"] == 3.0 / 8.0
    with pytest.raises(ScenarioError, match="failed takes no argument"):
        parse_objective("miss_rms+failed(2)", scenario)


def test_the_best_held_out_record_fails_the_fewest_runs():
    """``best_heldout`` picks among the ``eval_every`` records as the training check picks:
    a lower objective with more failed runs loses to a higher one with fewer, the objective
    decides between equals (the earliest of equal records), a record with no ok run (NaN)
    ranks last among those that fail as many runs; brute force over the records' pairs."""
    nan = float("nan")
    scored = [(5.0, 2), (9.0, 0), (nan, 0), (8.0, 0), (3.0, 1), (8.0, 0)]
    history = [dict(step=s, runs=8 * (s + 1), wall_s=1.0 * s) for s in range(8)]
    for rec, (value, failed) in zip(history[1:], scored, strict=False):
        rec.update(heldout=value, heldout_failed=failed)
    result = tune_module.TuneResult(
        None, None, ["k"], [1.0], [1.0], "miss_rms", "adam", 0, 8, 8, history, None, 0.0, 0.0
    )
    records = [h for h in history if "heldout" in h]

    def beats(a, b):  # a ranks strictly before b, by the written rule
        if a["heldout_failed"] != b["heldout_failed"]:
            return a["heldout_failed"] < b["heldout_failed"]
        va = a["heldout"] if a["heldout"] == a["heldout"] else float("inf")
        vb = b["heldout"] if b["heldout"] == b["heldout"] else float("inf")
        return va < vb

    first = [a for a in records if not any(beats(b, a) for b in records)][0]
    assert result.best_heldout() is first and first["step"] == 4  # 8.0, none failed
    assert result.runs_to_reach(result.best_heldout()) == (40, 4.0)
    assert dataclasses.replace(result, history=history[:1]).best_heldout() is None


def test_a_user_objective_that_takes_runs_tells_padding_from_failed_runs(monkeypatch):
    """A callable ``fn(outcomes, weights, runs)`` gets the batch's mask (1: a real run, 0:
    padding) besides the counted runs, so that it can price failures; ``fn(outcomes,
    weights)`` is called as it always was."""
    scenario = toy()
    (gain,) = resolve_gains(scenario, ["guidance.pn.n"])
    ok, time_out = int(gj.Status.ok), int(gj.Status.time_out)
    out = _toy_outcomes([ok, time_out, ok, ok, ok, time_out], [3.0, 900.0, 4.0, 1.0, 2.0, 900.0])
    seen = {}

    def priced(outcomes, weights, runs):
        seen["weights"], seen["runs"] = np.asarray(weights), np.asarray(runs)
        return jnp.sum(weights * outcomes.miss_m) + 100.0 * jnp.sum(runs - weights)

    def plain(outcomes, weights):
        seen["plain"] = np.asarray(weights)
        return jnp.sum(weights * outcomes.miss_m)

    idx = None
    for fn in (priced, plain):
        problem = tune_module.TuningProblem(scenario, [gain], parse_objective(fn, scenario), 0)
        monkeypatch.setattr(problem, "fn", lambda *a: out)
        idx, valid = problem.padded(np.arange(4), size=6)  # runs 0..3 real, 2 padding
        value, _ = problem.hard(problem.args, np.array([3.0]), idx, valid)
        if fn is priced:
            np.testing.assert_array_equal(seen["runs"], [1, 1, 1, 1, 0, 0])
            np.testing.assert_array_equal(seen["weights"], [1, 0, 1, 1, 0, 0])
            assert float(value) == 3.0 + 4.0 + 1.0 + 100.0 * 1  # one failed real run
        else:
            np.testing.assert_array_equal(seen["plain"], [1, 0, 1, 1, 0, 0])
            assert float(value) == 8.0
    # no mask given (the held-out table's resamples): every run is a real run
    counted = jnp.asarray([1.0, 0.0, 1.0, 1.0, 1.0, 0.0])
    assert float(parse_objective(priced, scenario).value(out, counted)) == 10.0 + 100.0 * 2


def test_heldout_table_has_the_failed_fraction_of_every_held_out_run(monkeypatch):
    """With ``failed`` in the objective the held-out bootstrap resamples every run: the
    ``failed`` row is each side's failed fraction, the other terms are over the runs ok with
    both gains, the interval the numpy bootstrap of those per-resample differences."""
    scenario = toy()
    objective = parse_objective("miss_rms+100*failed", scenario)
    (gain,) = resolve_gains(scenario, ["guidance.pn.n"])
    problem = tune_module.TuningProblem(scenario, [gain], objective, seed=0)
    rng = np.random.default_rng(5)
    n = 12
    ok, failed = int(gj.Status.ok), int(gj.Status.propellant)
    fail = {1.0: np.isin(np.arange(n), [2, 7]), 2.0: np.isin(np.arange(n), [2, 4, 9])}
    miss = {g: rng.uniform(1.0, 50.0, n) for g in fail}
    sides = {g: _toy_outcomes(np.where(fail[g], failed, ok), miss[g]) for g in fail}
    monkeypatch.setattr(problem, "hard_outcomes", lambda gains, idx: sides[float(gains[0])])
    resamples = 40  # each an eager evaluation of the objective per row and side
    bootstrap = lambda *a: paired_interval(*a, resamples=resamples)  # noqa: E731
    monkeypatch.setattr(tune_module.evaluation, "paired_interval", bootstrap)
    heldout = tune_module.evaluate_heldout(problem, [1.0], [2.0], runs=n, chunk=n)
    rows = {r["metric"]: r for r in heldout["rows"]}
    assert heldout["failed"] == dict(initial=2, tuned=3) and heldout["paired_runs"] == 8

    def by_hand(g, i):
        both = ~(fail[1.0] | fail[2.0])[i]
        miss_rms = np.sqrt(np.mean(miss[g][i][both] ** 2))
        return dict(miss_rms=miss_rms, failed=np.mean(fail[g][i]))

    every = np.arange(n)
    for side, g in (("initial", 1.0), ("tuned", 2.0)):
        terms = by_hand(g, every)
        assert rows["failed"][side] == terms["failed"]
        np.testing.assert_allclose(rows["miss_rms"][side], terms["miss_rms"], rtol=1e-12)
        total = terms["miss_rms"] + 100.0 * terms["failed"]
        np.testing.assert_allclose(rows["objective"][side], total, rtol=1e-12)
    draws = np.random.default_rng(0)
    diffs = []
    for _ in range(resamples):
        d = draws.integers(0, n, size=n)
        diffs.append(by_hand(2.0, d)["failed"] - by_hand(1.0, d)["failed"])
    lo, hi = np.quantile(diffs, [0.025, 0.975])
    np.testing.assert_allclose([rows["failed"]["ci_low"], rows["failed"]["ci_high"]], [lo, hi])
    assert "failed" in tune_module.heldout_table(heldout)


def test_heldout_table_gives_a_user_objective_that_takes_runs_every_held_out_run(monkeypatch):
    """A user objective that takes ``runs`` prices failed runs: the held-out table evaluates
    it on every held-out run with its side's own ok runs as weights (a hand count of each
    side's failures and mean miss), its interval the bootstrap of those; a two-argument
    objective stays over the runs ok with both gains."""
    scenario = toy()
    (gain,) = resolve_gains(scenario, ["guidance.pn.n"])
    n = 12
    ok, failed = int(gj.Status.ok), int(gj.Status.nan)
    fail = {1.0: np.isin(np.arange(n), [2, 7]), 2.0: np.isin(np.arange(n), [2, 4, 9, 10])}
    miss = {g: np.random.default_rng(6).uniform(1.0, 50.0, n) * g for g in fail}
    sides = {g: _toy_outcomes(np.where(fail[g], failed, ok), miss[g]) for g in fail}

    def priced(outcomes, weights, runs):
        mean = jnp.sum(weights * outcomes.miss_m) / jnp.maximum(jnp.sum(weights), 1.0)
        return mean + 100.0 * jnp.sum(runs - weights) / jnp.sum(runs)

    def plain(outcomes, weights):
        return jnp.sum(weights * outcomes.miss_m) / jnp.maximum(jnp.sum(weights), 1.0)

    resamples = 30
    bootstrap = lambda *a: paired_interval(*a, resamples=resamples)  # noqa: E731
    monkeypatch.setattr(tune_module.evaluation, "paired_interval", bootstrap)
    rows = {}
    for fn in (priced, plain):
        problem = tune_module.TuningProblem(scenario, [gain], parse_objective(fn, scenario), 0)
        monkeypatch.setattr(problem, "hard_outcomes", lambda gains, idx: sides[float(gains[0])])
        heldout = tune_module.evaluate_heldout(problem, [1.0], [2.0], runs=n, chunk=n)
        assert heldout["failed"] == dict(initial=2, tuned=4)
        (rows[fn.__name__],) = heldout["rows"]

    def by_hand(g, i, paired=False):
        keep = ~(fail[1.0] | fail[2.0])[i] if paired else ~fail[g][i]
        if paired:
            return miss[g][i][keep].mean()
        return miss[g][i][keep].mean() + 100.0 * fail[g][i].sum() / len(i)

    every = np.arange(n)
    for side, g in (("initial", 1.0), ("tuned", 2.0)):
        np.testing.assert_allclose(rows["priced"][side], by_hand(g, every), rtol=1e-12)
        np.testing.assert_allclose(rows["plain"][side], by_hand(g, every, True), rtol=1e-12)
    draws = np.random.default_rng(0)
    diffs = []
    for _ in range(resamples):
        d = draws.integers(0, n, size=n)
        diffs.append(by_hand(2.0, d) - by_hand(1.0, d))
    lo, hi = np.quantile(diffs, [0.025, 0.975])
    np.testing.assert_allclose([rows["priced"]["ci_low"], rows["priced"]["ci_high"]], [lo, hi])


def test_auto_gradient_mode_follows_the_number_of_parameters(monkeypatch):
    """``gradient="auto"`` runs forward mode below ``REVERSE_FROM`` parameters and reverse
    mode from it on, or the cheaper by a system's measured costs; both give the steps the
    named mode gives (the same gradient)."""
    from gnc_jax.tuning import optimisers

    assert optimisers.gradient_mode("auto", optimisers.REVERSE_FROM - 1) == "forward"
    assert optimisers.gradient_mode("auto", optimisers.REVERSE_FROM) == "reverse"
    assert optimisers.gradient_mode("forward", 100) == "forward"
    # a system's measured costs: forward 3 + p plain runs, reverse 4.5 (on one device while
    # forward mode shards over two: 9)
    costs = (3.0, 1.0, 4.5)
    assert [optimisers.gradient_mode("auto", p, costs) for p in (1, 2)] == ["forward", "reverse"]
    on_one = [optimisers.gradient_mode("auto", p, costs, 2) for p in (5, 6, 7)]
    assert on_one == ["forward", "forward", "reverse"]
    kw = dict(batch=8, steps=3, heldout_runs=0, learning_rate=0.2, check_runs=0, seed=2)
    fwd = tune(toy(), "guidance.pn.n", "miss_rms", gradient="forward", **kw)
    rev = tune(toy(), "guidance.pn.n", "miss_rms", gradient="reverse", **kw)
    auto = tune(toy(), "guidance.pn.n", "miss_rms", **kw)
    assert [h["gains"] for h in auto.history] == [h["gains"] for h in fwd.history]
    monkeypatch.setattr(optimisers, "REVERSE_FROM", 1)
    auto_rev = tune(toy(), "guidance.pn.n", "miss_rms", **kw)
    assert [h["gains"] for h in auto_rev.history] == [h["gains"] for h in rev.history]
    assert (auto.gradient, auto_rev.gradient) == ("forward", "reverse")  # as the result says
    assert auto.summary()["gradient"] == "forward"
    np.testing.assert_allclose(
        [h["gains"] for h in rev.history], [h["gains"] for h in fwd.history], rtol=1e-9
    )
    with pytest.raises(ScenarioError, match="gradient"):
        tune(toy(), "guidance.pn.n", gradient="sideways", **kw)


def test_the_tuners_programs_are_traced_in_the_systems_loop_layout():
    """A tuning flies the loops in the layout a study of its system flies on that platform
    (``for_platform``, or the one set by ``using_loop_shape`` when the problem is built),
    wherever its programs are first called."""
    from gnc_jax._numerics import LoopShape, for_platform, loop_shape, using_loop_shape

    scenario = toy()
    objective = parse_objective("miss_rms", scenario)
    gains = resolve_gains(scenario, ["guidance.pn.n"])
    problem = tune_module.TuningProblem(scenario, gains, objective, seed=0)
    assert problem.loop_shape == for_platform(jax.default_backend(), problem.system)
    shape = LoopShape(fence=False, unroll=3, early_exit=False)
    with using_loop_shape(shape):
        placed = tune_module.TuningProblem(scenario, gains, objective, seed=0)
    assert placed.loop_shape == shape
    probe = lambda: lambda x: x + loop_shape().unroll  # noqa: E731  (read at trace time)
    assert float(placed.jitted("layout-probe", probe)(1.0)) == 4.0
    assert float(problem.jitted("layout-probe", probe)(1.0)) == 1.0 + problem.loop_shape.unroll
    executable, _ = placed.compiled("layout-probe", probe, 1.0)
    assert float(executable(1.0)) == 4.0
