"""The accelerator's loop layout, run on the CPU: unfenced and unrolled closed loops give every
system's per-run outcomes to its ``batch_tolerance`` (statuses and integers identical), so the
layout a GPU compiles is checked where CI runs. The layout is chosen per platform; a caller may
force one (``using_loop_shape``), and compiled programs are cached per layout.

The one loop ``early_exit`` changes, the capsule corrector's predictor steps, is checked with
the accelerator's fixed bound at the corrector (tests/guidance/entry/test_skip_entry.py), where
it is the only difference: in the closed loop, unrolled whole, it takes most of a compilation.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from short_impactor import SHORT

import gnc_jax as gj
from gnc_jax import montecarlo
from gnc_jax._numerics import (
    LoopShape,
    computed_once,
    for_platform,
    layout_for,
    loop_shape,
    rarely,
    using_loop_shape,
)

ACCELERATOR = LoopShape(fence=False, unroll=4, early_exit=False)  # the accelerators' default


def closed_loop_layout(system) -> LoopShape:
    """The accelerator's layout of ``system``, checked here in closed loop: its fence and
    unrolling; the predictor rounds' bound (``early_exit``) is checked at the corrector."""
    return for_platform("gpu", system)._replace(early_exit=True)


def example(name):
    system = gj.get_system(name)
    return gj.load_scenario(system.example, overrides=dict(system.test_overrides))


# The systems whose compiled loop the layout changes (fenced guidance steps, unrolled control
# or truth sub-steps); the midcourse loop is one scan over navigation fixes, the same program
# in both layouts.
@pytest.mark.parametrize("name", ["impactor", "intercept", "capsule"])
def test_accelerator_layout_on_cpu_matches_within_batch_tolerance(name):
    """Five runs in chunks of four on all devices: in the CPU's layout that is the program
    tests/test_family.py compiles for its chunked study, read from the session's XLA cache."""
    assert name in gj.systems()
    scenario = example(name)
    study = dict(runs=5, seed=3, chunk_size=4, progress=False)
    cpu = gj.run_study(scenario, **study)
    with using_loop_shape(closed_loop_layout(gj.get_system(name))):  # what a GPU compiles
        acc = gj.run_study(scenario, **study)
    assert acc.compile_s > 0.0, "the forced layout must compile its own program"
    assert_same_outcomes(acc, cpu, gj.get_system(name))


def assert_same_outcomes(got, reference, system):
    """``got``'s per-run outcomes equal ``reference``'s (a study without failed runs) within
    ``system.batch_tolerance``; statuses and counts identical."""
    assert reference.summary()["failed"] == 0, reference.summary()["failed_by_status"]
    rtol, atol = system.batch_tolerance
    for field, x in reference.outcomes.items():
        x, y = np.asarray(x), np.asarray(got.outcomes[field])
        if np.issubdtype(x.dtype, np.floating):
            np.testing.assert_allclose(y, x, rtol=rtol, atol=atol, err_msg=field)
        else:
            np.testing.assert_array_equal(y, x, err_msg=field)


def test_platform_defaults_and_override():
    assert for_platform("cpu") == LoopShape(fence=True, unroll=1)
    assert not for_platform("gpu").fence and for_platform("gpu").unroll > 1
    assert not for_platform("gpu").early_exit and for_platform("cpu").early_exit
    assert for_platform("gpu") == ACCELERATOR
    # a system may declare its own accelerator layout (the intercept's CPU one is the platform's)
    intercept = gj.get_system("intercept")
    assert for_platform("gpu", intercept) == LoopShape(
        fence=False, unroll=8, early_exit=False, components=True
    )
    assert for_platform("gpu", gj.get_system("impactor")) == LoopShape(
        fence=False, unroll=5, early_exit=False, components=True
    )
    assert for_platform("gpu", gj.get_system("capsule")) == for_platform("gpu")
    assert for_platform("cpu", intercept) == for_platform("cpu")
    # and its own CPU layout: the impactor unrolls its control steps, fenced as the CPU's
    impactor_cpu = for_platform("cpu", gj.get_system("impactor"))
    assert impactor_cpu.unroll > 1 and impactor_cpu._replace(unroll=1) == for_platform("cpu")
    assert loop_shape() == for_platform("cpu")  # CI's backend
    with using_loop_shape(ACCELERATOR):
        assert loop_shape() == ACCELERATOR
    assert loop_shape() == for_platform("cpu")
    with pytest.raises(ValueError, match="unroll"):
        with using_loop_shape(LoopShape(unroll=0)):
            pass


def test_a_fence_is_a_conditional_only_when_the_layout_fences():
    import jax
    import jax.numpy as jnp

    def traced(x):  # a new function per trace: JAX caches a function's trace, not the layout
        return str(
            jax.make_jaxpr(lambda t, y: computed_once(lambda z: jnp.sin(z) * 2.0, t, y))(1.0, x)
        )

    assert "cond" in traced(jnp.ones(3))
    with using_loop_shape(ACCELERATOR):
        assert "cond" not in traced(jnp.ones(3))
        value = computed_once(lambda z: jnp.sin(z) * 2.0, 1.0, jnp.ones(3))
    np.testing.assert_allclose(value, np.sin(np.ones(3)) * 2.0, rtol=1e-15)


def test_compiled_programs_are_cached_per_layout():
    keys = [k for k in montecarlo._COMPILED if len(k) > 3]
    shapes = {k[3] for k in keys}
    if keys:  # after the parametrised test in this module: both layouts were cached apart
        assert closed_loop_layout(gj.get_system("impactor")) in shapes
        assert for_platform("cpu") in shapes
    else:
        pytest.fail("the study test above should have compiled programs in this process")


def _brute(pred, x, a):
    return np.where(pred, x * a + 1.0, x - a)


@pytest.mark.parametrize("taking", [0, 3, 8, 11])
def test_rarely_gives_each_run_its_branch_whatever_the_count(taking):
    """Under vmap, none, a few (gathered), and more runs than the gathered lanes (the whole
    batch): each run gets its branch's value, with a batched and an unbatched closed-over
    value and an unbatched operand; unbatched it is a conditional; forward mode through it."""
    n = 24
    x = jnp.linspace(-1.0, 2.0, n)
    pred = np.zeros(n, bool)
    pred[np.random.default_rng(taking).choice(n, taking, replace=False)] = True
    shift = jnp.arange(n) * 0.5

    def f(p, xi, s, a):
        return rarely(
            p,
            lambda o: (o[0] * o[1] + 1.0, jnp.stack([s, o[0]])),
            lambda o: (o[0] - o[1], jnp.stack([s, -o[0]])),
            (xi, a),
            1 / 3,  # 8 lanes for 24 runs
        )

    vf = jax.jit(jax.vmap(f, in_axes=(0, 0, 0, None)))
    y, pair = vf(jnp.asarray(pred), x, shift, 1.5)
    np.testing.assert_allclose(y, _brute(pred, np.asarray(x), 1.5), rtol=1e-15, atol=0)
    np.testing.assert_array_equal(pair[:, 0], shift)
    np.testing.assert_array_equal(pair[:, 1], np.where(pred, x, -x))
    i = int(np.argmax(pred)) if taking else 0
    single = jax.jit(f)(jnp.asarray(pred[i]), x[i], shift[i], 1.5)[0]
    np.testing.assert_allclose(single, _brute(pred[i], float(x[i]), 1.5), rtol=1e-15)
    _, dy = jax.jvp(lambda a: vf(jnp.asarray(pred), x, shift, a)[0], (1.5,), (1.0,))
    np.testing.assert_allclose(dy, np.where(pred, x, -1.0), rtol=0, atol=1e-15)


@pytest.mark.parametrize("gravity", [False, True])
def test_impactor_rare_layout_matches_within_batch_tolerance(gravity):
    """The impactor's intervals coasted by every run and flown again by the runs that fired
    (LoopShape.rare), forced on a study of 32 runs a device (8 lanes gathered; the first
    intervals fire in every run: the whole batch): per-run outcomes equal the default
    layout's within batch_tolerance (the gathered lanes are a program of another width),
    statuses and counts identical; with the target's gravity on, the coast's RK4 step
    evaluates it."""
    system = gj.get_system("impactor")
    extra = ["dynamics.mu_target_m3s2=5.0"] if gravity else []
    scenario = gj.load_scenario(system.example, overrides=SHORT + extra)
    study = dict(runs=64, seed=11, chunk_size=64, progress=False)
    default = gj.run_study(scenario, **study)
    with using_loop_shape(for_platform("cpu", system)._replace(rare=1 / 8)):
        rare = gj.run_study(scenario, **study)
    assert rare.compile_s > 0.0, "the rare layout must compile its own program"
    assert np.asarray(default.outcomes["firings"]).min() >= 1
    assert_same_outcomes(rare, default, system)


def test_a_dask_worker_compiles_the_layout_of_the_whole_study(monkeypatch):
    """A worker's chunk (run_chunk, one Dask task) is compiled in the layout a local study of
    the whole study's runs would be, at the worker's own lanes a device, not its chunk's."""
    from gnc_jax import montecarlo
    from gnc_jax._numerics import RareLayout, explicit_loop_shape
    from gnc_jax.backend import select

    system = gj.get_system("impactor")
    monkeypatch.setattr(type(system), "rare_layout", RareLayout(1 / 32, 1000, min_lanes=8))
    scenario = gj.load_scenario(system.example, overrides=SHORT)
    built = montecarlo.build_on(select("cpu"), scenario)
    seen = []

    class Compiled(Exception):
        pass

    def compile_(*args):
        seen.append(explicit_loop_shape())
        raise Compiled

    monkeypatch.setattr(montecarlo, "_compile", compile_)
    for study_runs in (1000, 999, None):
        with pytest.raises(Compiled):
            montecarlo.run_chunk(scenario, 11, 0, 64, 64, built=built, study_runs=study_runs)
    on = for_platform("cpu", system)._replace(rare=1 / 32)
    assert seen == [on, None, None]  # None: the platform's default layout


def test_a_study_turns_the_rare_layout_on_only_where_it_pays():
    from gnc_jax.backend import Backend
    from gnc_jax.montecarlo import study_layout

    system = gj.get_system("impactor")
    rare = system.rare_layout
    cpu = Backend("cpu", "cpu", (0, 1), 1 << 34)
    gpu = Backend("gpu", "NVIDIA H100", (0,), 1 << 36)

    def shape(backend, runs, lanes):
        with study_layout(system, backend, runs, lanes):
            return layout_for(backend.platform, system)

    on = for_platform("cpu", system)._replace(rare=rare.fraction)
    assert shape(cpu, rare.min_runs, rare.min_lanes) == on
    assert shape(cpu, rare.min_runs - 1, rare.min_lanes).rare == 0.0
    assert shape(cpu, rare.min_runs, rare.min_lanes - 1).rare == 0.0
    assert shape(gpu, rare.min_runs, rare.min_lanes) == for_platform("gpu", system)
    assert gj.get_system("capsule").rare_layout is None
    assert shape(cpu, 10**6, 2048) == on
    chosen = for_platform("cpu", system)._replace(unroll=1)
    with using_loop_shape(chosen):  # a layout the caller chose is kept
        assert shape(cpu, 10**6, 2048) == chosen
