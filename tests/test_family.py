"""Family tests: every registered system and every law of its family, by being registered.

Like diffrax's ``all_ode_solvers``: the cases are read from the registry at collection time, so
a new system (built-in or a user's, e.g. ``tests/toy_system.py``) or a new law registered into
a family is tested here without new test code. Each case runs the system's ``example`` scenario
with its ``test_overrides`` (a cheap version of the same code paths); the tuning tests take the
cases with tunable leaves.

The README's determinism statement is checked at CI size, for every system to its own
tolerance: several chunks with a ragged last one, split over all devices, against the per-run
loop on one device (a 2000-run study in chunks of 300 exercises nothing more).
"""

import dataclasses
import json
import os
import pathlib
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax import montecarlo
from gnc_jax.params import declared_params, file_name, from_scenario, schema_of
from gnc_jax.systems import tunable_leaf

CASES = [
    pytest.param(name, law, id=f"{name}-{law}" if law else name)
    for name, system in gj.systems().items()
    for law in (list(system.laws()) or [None])
]


def example(name, law=None):
    system = gj.get_system(name)
    overrides = dict(system.test_overrides)
    if law is not None:
        overrides["guidance.law"] = law
    return gj.load_scenario(system.example, overrides=overrides)


def tunables(name, law):
    names = gj.get_system(name).tunable_names()
    return [t for t in names if law is None or t.startswith(f"guidance.{law}.")]


# the cases the tuning tests below apply to: tunable leaves (and, for the gradient, a smooth
# objective)
TUNABLE_CASES = [case for case in CASES if tunables(*case.values)]
SMOOTH_CASES = [
    case
    for case in TUNABLE_CASES
    if type(gj.get_system(case.values[0])).smooth_objective
    is not gj.AbstractSystem.smooth_objective
]


def assert_outcomes_equal(a: dict, b: dict, rows=slice(None), tolerance=(1e-9, 1e-9)):
    assert a.keys() == b.keys()
    for field in a:
        x, y = np.asarray(a[field])[rows], np.asarray(b[field])
        if np.issubdtype(x.dtype, np.floating):
            rtol, atol = tolerance
            np.testing.assert_allclose(x, y, rtol=rtol, atol=atol, err_msg=field)
        else:
            np.testing.assert_array_equal(x, y, err_msg=field)


@pytest.mark.parametrize("name, law", CASES)
def test_batch_equals_per_run_loop_chunking_and_devices(name, law):
    """The README's determinism statement: statuses and integer outcomes identical, floats
    within ``batch_tolerance``, whatever the chunking and the number of devices -- and equal to
    a loop over single runs, so a run's outcome does not depend on how many runs the study has.
    One study, all differences at once (one compilation per system): five runs in chunks of
    four on all devices (two host devices on a 2-core CPU, one GPU), so several runs share a
    device's batch, the runs are split over the devices and the last chunk is ragged (padded);
    each run against the same run simulated alone, unbatched, on one device (with its trace:
    the program the reports and the trace tests fly, compiled once)."""
    scenario = example(name, law)
    study = gj.run_study(scenario, runs=5, seed=7, chunk_size=4, progress=False)
    assert study.n_devices == len(jax.devices()) and study.chunk_size == 4
    assert study.summary()["failed"] == 0, study.summary()["failed_by_status"]
    tolerance = gj.get_system(name).batch_tolerance
    for i in range(5):
        one, _ = gj.simulate_one(scenario, index=i, seed=7, record=True)
        assert_outcomes_equal(study.outcomes, one._asdict(), rows=i, tolerance=tolerance)


@pytest.mark.parametrize("name, law", CASES)
def test_a_failed_run_is_counted_and_left_out(name, law, monkeypatch):
    """A run whose outcome is not finite gets the ``nan`` status, is counted in ``failed`` and
    is left out of the statistics, whatever the system. The odd runs' first float outcome is
    made NaN on its way out of the compiled study -- the executable the chunking test above
    compiled, so nothing is compiled again."""
    real_compile = montecarlo._compile

    def poisoning(*args):
        compiled, compile_s = real_compile(*args)

        def run(sim, law, seed, indices):
            out = compiled(sim, law, seed, indices)
            field = next(
                f for f in out._fields[1:] if np.issubdtype(getattr(out, f).dtype, np.floating)
            )
            odd = np.asarray(indices) % 2 == 1
            return out._replace(**{field: np.where(odd, np.nan, np.asarray(getattr(out, field)))})

        return run, compile_s

    monkeypatch.setattr(montecarlo, "_compile", poisoning)
    study = gj.run_study(example(name, law), runs=4, seed=7, progress=False)
    bad = np.arange(4) % 2 == 1
    np.testing.assert_array_equal(study.status == gj.Status.nan, bad)
    summary = study.summary()
    assert summary["failed"] == int(bad.sum())
    assert summary["failed_by_status"] == {"nan": int(bad.sum())}
    for key, value in summary.items():
        if isinstance(value, float):
            assert np.isfinite(value), key


@pytest.mark.parametrize("name, law", SMOOTH_CASES)
def test_gradient_of_a_tunable_leaf_matches_central_differences(name, law):
    system = gj.get_system(name)
    leaves = tunables(name, law)
    params, hard_law = gj.build(example(name, law))
    relaxed = hard_law.relax(temperature=0.1)  # a smooth switch: differences resolve it
    _, attribute = tunable_leaf(system, leaves[0])

    def objective(value):
        tuned = eqx.tree_at(lambda l: getattr(l, attribute), relaxed, value)
        keys = jax.vmap(lambda i: gj.run_key(1, i))(jnp.arange(2))
        out = jax.vmap(lambda k: system.simulate(params, tuned, k)[0])(keys)
        return system.smooth_objective(out)

    # forward mode: one leaf, and loops with data-dependent trip counts (while_loop) allow it.
    # One program gives both the derivative and the values the differences are taken of.
    value_and_derivative = jax.jit(lambda v: jax.jvp(objective, (v,), (jnp.ones_like(v),)))
    x = jnp.asarray(getattr(hard_law, attribute), dtype=jnp.float64)
    grad = float(value_and_derivative(x)[1])
    assert np.isfinite(grad)
    # The relaxed loop keeps a few jumps (an ignition, at the 0.5 level of the relaxed switch,
    # picks a new execution-error draw); a central difference whose step straddles one is not
    # a derivative. Two small steps: the gradient must match the difference at one of them.
    fds = []
    for rel in (1e-5, 1e-6):
        h = rel * max(1.0, abs(float(x)))
        up, down = value_and_derivative(x + h)[0], value_and_derivative(x - h)[0]
        fds.append(float((up - down) / (2 * h)))
    assert any(abs(fd) > 0.0 for fd in fds), "the objective does not depend on the leaf"
    errors = [abs(grad - fd) / max(abs(fd), 1e-300) for fd in fds]
    assert min(errors) < 5e-3, f"gradient {grad} vs central differences {fds}"


@pytest.mark.parametrize("name, law", TUNABLE_CASES)
def test_new_gain_values_reuse_the_compiled_study(name, law):
    """A new gain value runs on the executable the scenario's study compiled (4 runs on all
    devices, as in the chunking test above: nothing is compiled in this test)."""
    leaves = tunables(name, law)
    scenario = example(name, law)
    value = scenario[leaves[0]]
    a = gj.run_study(scenario, runs=4, seed=0, progress=False)
    b = gj.run_study(
        scenario.with_overrides({leaves[0]: value * 0.8}), runs=4, seed=0, progress=False
    )
    assert b.compile_s == 0.0  # gains are arguments of the executable, not constants
    assert not all(np.array_equal(a.outcomes[f], b.outcomes[f]) for f in a.outcomes)


@pytest.mark.parametrize("name, law", [c for c in CASES if c.values[1] is not None])
def test_law_parameters_are_declared_once(name, law):
    """The [guidance.<law>] table is the law's declared fields, and the law a system builds
    holds every declared field converted from the scenario's table by its declaration (except
    fields whose SI value depends on other sections, e.g. trigger thresholds in units of the
    engine's impulse bit)."""
    system = gj.get_system(name)
    cls = system.laws()[law]
    assert system.schema()[f"guidance.{law}"] == schema_of(cls)
    scenario = example(name, law)
    table = scenario.config["guidance"][law]
    _, built = gj.build(scenario)
    assert type(built) is cls
    for attribute, spec in declared_params(cls).items():
        if not spec.derived:
            expected = spec.to_si(table[file_name(attribute, spec)])
            np.testing.assert_array_equal(getattr(built, attribute), expected, err_msg=attribute)


def test_a_system_registered_outside_the_package_runs_from_the_command_line(tmp_path):
    """``gnc-jax run`` / ``report`` on the toy system of tests/toy_system.py, registered from
    outside ``gnc_jax/`` through the plugin variable, in a fresh process."""
    tests_dir = pathlib.Path(__file__).parent
    env = {**os.environ, "GNC_JAX_PLUGINS": "toy_system", "GNC_JAX_HOST_DEVICES": "1"}
    env["PYTHONPATH"] = os.pathsep.join([str(tests_dir), env.get("PYTHONPATH", "")])
    out = tmp_path / "toy"
    run = [sys.executable, "-m", "gnc_jax", "run", str(tests_dir / "toy.toml"), "--runs", "50"]
    done = subprocess.run(run + ["--out", str(out)], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kind"] == "toy-intercept" and summary["runs"] == 50
    assert summary["failed"] == 0 and summary["miss_rms_m"] < 20.0
    report = subprocess.run(
        [sys.executable, "-m", "gnc_jax", "report", str(out)], env=env, capture_output=True
    )
    assert report.returncode == 0, report.stderr
    assert (out / "miss.png").read_bytes()[:4] == b"\x89PNG"
    # without the plugin the kind is unknown, in one line
    env.pop("GNC_JAX_PLUGINS")
    refused = subprocess.run(run, env=env, capture_output=True, text=True)
    assert refused.returncode == 2
    assert refused.stderr.strip() == (
        "gnc-jax: error: scenario.kind: 'toy-intercept'; allowed: one of capsule, impactor, "
        "intercept, midcourse"
    )


@pytest.mark.parametrize("name", list(gj.systems()))
def test_parameter_modules_declare_every_field_once(name):
    """Every field of a system's parameter Modules is declared with ``param`` (section, units,
    range, default in the file's units) — no field keeps a hand-written default of its own —
    and appears in the system's schema; building the Module from the example scenario reads
    each field from its declared section."""
    system = gj.get_system(name)
    config = example(name).config
    schema = system.schema()
    for cls in system.parameter_modules:
        specs = declared_params(cls)
        assert set(specs) == {f.name for f in dataclasses.fields(cls)}, cls.__name__
        built = from_scenario(cls, config)
        for attribute, spec in specs.items():
            assert schema[spec.section][file_name(attribute, spec)] == spec.field
            expected = spec.to_si(config[spec.section][file_name(attribute, spec)])
            np.testing.assert_array_equal(getattr(built, attribute), expected, err_msg=attribute)
