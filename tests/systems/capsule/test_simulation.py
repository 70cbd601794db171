"""Lunar skip entry: chute-deploy location and the closed loop (seed 003).

Batching, chunking, failed-run accounting, gradients and recompilation are checked for every
system and law by tests/test_family.py; the guided chute point and the switch point against
the seed are checked by ``test_paper_scale_skip_entry`` (100 runs in CI).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.dynamics.atmosphere import Atmosphere
from gnc_jax.dynamics.entry import (
    EarthModel,
    EntryArgs,
    EntryConditions,
    EntryVehicle,
    entry_state_from_conditions,
    entry_vector_field,
)
from gnc_jax.guidance.entry.base import flight_variables, hermite_crossing, hermite_state
from gnc_jax.integrate import rk4_step


def test_chute_crossing_is_located_inside_the_step():
    """Hermite location with 0.5 s steps vs the crossing of a 1 ms RK4 integration."""
    earth, atm = EarthModel(), Atmosphere()
    args = EntryArgs(EntryVehicle(), earth, atm, jnp.asarray(0.7))
    y = entry_state_from_conditions(
        EntryConditions(12.3e3, 250.0, np.radians(-55.0), 0.6, 1.0, 0.2), earth
    )
    level = 10e3
    f = lambda t, y: entry_vector_field(t, y, args)  # noqa: E731

    def crossing(dt, n):
        def body(c, _):
            y, t, found, t_x, r_x = c
            y1 = rk4_step(entry_vector_field, t, y, dt, args)
            f0, f1 = flight_variables(y, earth), flight_variables(y1, earth)
            hit = ~found & (f1.altitude_m < level)
            s = hermite_crossing(f0.altitude_m, f0.hdot_mps, f1.altitude_m, f1.hdot_mps, dt, level)
            st = hermite_state(y, f(t, y).v, y1, f(t + dt, y1).v, dt, s)
            return (
                y1,
                t + dt,
                found | hit,
                jnp.where(hit, t + s * dt, t_x),
                jnp.where(hit, st.r, r_x),
            ), None

        init = (y, 0.0, jnp.asarray(False), 0.0, y.r)
        (_, _, found, t_x, r_x), _ = jax.lax.scan(body, init, None, length=n)
        return found, t_x, r_x

    found, t_coarse, r_coarse = jax.jit(crossing, static_argnums=1)(0.5, 60)
    ok, t_fine, r_fine = jax.jit(crossing, static_argnums=1)(0.001, 30000)
    assert bool(found) and bool(ok)
    assert 1.0 < float(t_fine) < 29.0
    assert abs(float(t_coarse) - float(t_fine)) < 2e-3  # s
    assert float(jnp.linalg.norm(r_coarse - r_fine)) < 0.5  # m (vs ~150 m per step)


@pytest.fixture(scope="module")
def capsule_scenario():
    return gj.load_scenario("lunar-skip-entry")


def test_flight_stopped_when_down_equals_the_full_length_scan(capsule_scenario):
    """Without a trace the guidance cycles stop once the flight is down (a while_loop); with
    one they run the whole max_time_s (a scan). A finished flight is frozen, so both give the
    same outcome, the scan being an independent loop structure. (Through ``simulate_one``: the
    per-run programs tests/test_family.py and tests/guidance/entry/test_skip_entry.py compile,
    read from the session's XLA cache.)"""
    sim, _ = gj.build(capsule_scenario)
    for i in range(2):
        short, _ = gj.simulate_one(capsule_scenario, index=i, seed=5, record=False)
        full, trace = gj.simulate_one(capsule_scenario, index=i, seed=5, record=True)
        assert trace.t_s.shape == (sim.n_control,)
        assert float(short.t_chute_s) < 0.7 * sim.n_control * sim.control_dt
        for name in short._fields:
            np.testing.assert_allclose(
                getattr(short, name), getattr(full, name), rtol=1e-12, atol=1e-9, err_msg=name
            )


@pytest.mark.slow
def test_downrange_gradient_wrt_tracking_gains_matches_finite_differences(
    capsule_scenario, paper_scale
):
    """The derivative of the chute downrange error with respect to the four second-entry
    feedback gains vs central differences at two steps.

    The derivative is pathwise: the bank reversals and the phase switches are hard logic, so
    a run where a reversal moves by a control step inside the difference interval has a
    difference quotient that depends on the step. Such runs are recognised by their two
    difference quotients disagreeing and skipped; the derivative must match on the others,
    and most runs must qualify.

    The derivatives are reverse mode's, the tuner's (the flight's cycles in equinox's
    checkpointed ``while_loop``, the corrector's solutions passing no derivative, since the
    tracking gains act after the last of them). With --paper-scale, forward mode's are checked
    against the differences too, and reverse mode's against forward mode's run by run, also for
    the reverse pass that differentiates every solution (a derivative of anything): what it
    passes back through them reaches no gain and must not spoil the rest (a NaN there would).
    The solutions' derivative itself is checked against differences of converged solves in
    tests/guidance/entry/test_skip_entry.py; forward mode through the relaxed law, the tuner's
    with few gains, in tests/test_family.py.

    CI runs two of the gains (range and Ḣ feedback) on two runs; --paper-scale all four on
    three."""
    import equinox as eqx

    from gnc_jax.systems.capsule.simulation import reverse_mode, simulate

    sim, law = gj.build(capsule_scenario)
    names = (
        ("k_range", "k_drag_load", "k_hdot", "k_range_rate")
        if paper_scale
        else ("k_range", "k_hdot")
    )
    n_gains, n_runs = len(names), 3 if paper_scale else 2

    def downrange(gains, i, sim=sim):
        tuned = eqx.tree_at(lambda l: tuple(getattr(l, n) for n in names), law, tuple(gains))
        return simulate(sim, tuned, gj.run_key(3, i))[0].downrange_err_km

    g0 = jnp.stack([getattr(law, n) for n in names])  # the scenario's defaults
    runs = jnp.arange(n_runs)
    steps = np.array([1e-6, 1e-7])
    offsets = np.concatenate([np.eye(n_gains) * h * s for h in steps for s in (1.0, -1.0)])
    shifted = g0 + jnp.asarray(offsets)
    # the values at the offset gains, (run, offset), in one program
    at = jax.vmap(lambda i: jax.vmap(lambda g: downrange(g, i))(shifted))
    vals = np.asarray(jax.jit(at)(runs)).reshape(n_runs, 2, 2, n_gains)
    fd = (vals[:, :, 0] - vals[:, :, 1]) / (2 * steps[None, :, None])  # (run, step, gain)
    scale = np.abs(fd[:, 1]).max(axis=1, keepdims=True) + 0.1
    smooth = (np.abs(fd[:, 0] - fd[:, 1]) / scale).max(axis=1) < 1e-3
    assert smooth.sum() >= n_runs - 1, fd

    def reverse(corrector_derivative):
        flown = reverse_mode(sim, corrector_derivative)
        backward = jax.vmap(lambda i, flown=flown: jax.grad(downrange)(g0, i, flown))
        return np.asarray(jax.jit(backward)(runs))  # (run, gain)

    jac = reverse(False)
    np.testing.assert_allclose(jac[smooth], fd[smooth, 1], rtol=1e-4, atol=1e-4 * scale.max())
    moved = np.abs(jac[smooth]).max(axis=1)  # the gains do move the chute point (km per unit)
    assert np.all(moved > 0.1) if paper_scale else moved.max() > 0.1
    if paper_scale:  # forward mode, one direction per gain; reverse mode's equal to it
        pushed = jax.vmap(lambda d, i: jax.jvp(lambda g: downrange(g, i), (g0,), (d,))[1])
        forward = jax.vmap(lambda i: pushed(jnp.eye(n_gains), jnp.full(n_gains, i)))
        tangents = np.asarray(jax.jit(forward)(runs))  # (run, gain)
        np.testing.assert_allclose(
            tangents[smooth], fd[smooth, 1], rtol=1e-4, atol=1e-4 * scale.max()
        )
        np.testing.assert_allclose(jac, tangents, rtol=1e-6)
        np.testing.assert_allclose(reverse(True), tangents, rtol=1e-6)


def test_reverse_mode_leaves_out_the_corrector_only_for_gains_acting_after_it():
    """The tuner's reverse pass differentiates the corrector's solutions unless every
    differentiated parameter is one the law reads only after the corrector's last cycle."""
    system = gj.get_system("capsule")
    sim, _ = gj.build(gj.load_scenario(system.example))
    after = ["guidance.skip_entry.k_range", "guidance.skip_entry.k_hdot_schedule[3]"]
    assert not system.reverse_mode(sim, after).corrector_derivative
    for names in (None, [], after + ["guidance.skip_entry.ratio_filter_gain"], ["entry.range_km"]):
        flown = system.reverse_mode(sim, names)
        assert flown.loop_kind == "checkpointed" and flown.corrector_derivative


def test_capsule_report_writes_the_paper_figures(capsule_scenario, tmp_path):
    from gnc_jax.report import report

    study = gj.run_study(capsule_scenario, runs=4, seed=1, progress=False)
    study.save(tmp_path)
    summary = study.summary()
    # the empirical 99.73 % interval lies inside the sample's range
    lo, hi = (float(x) for x in summary["downrange_err_km_central_99_73"].split(".."))
    # (the interval is printed to 0.01 km, so it may round just outside the extremes)
    d = summary["downrange_err_km"]
    assert d["min"] - 0.005 <= lo <= hi <= d["max"] + 0.005
    files = report(tmp_path)
    names = {p.rsplit("/", 1)[-1] for p in files}
    assert names == {
        "chute_scatter.png",
        "predictions.png",
        "miss_vs_ld.png",
        "altitude_range_fan.png",
        "bank_histories.png",
    }
    assert all((tmp_path / n).stat().st_size > 10_000 for n in names)
    # a study without an ok run: no run to fly again, the scatter of none (not a crash)
    from gnc_jax._status import Status
    from gnc_jax.results import load_results
    from gnc_jax.systems.capsule.figures import capsule_figures

    summary, runs, scenario = load_results(tmp_path)
    runs = dict(runs, status=np.full_like(runs["status"], Status.missed))
    assert capsule_scenario.system.figure_traces(summary, runs, scenario) == {}
    files = capsule_figures(summary, runs, scenario, tmp_path, {})
    assert [p.name for p in files] == ["chute_scatter.png"]


@pytest.mark.slow
def test_paper_scale_skip_entry(capsule_scenario, paper_scale):
    """Seed 003: every run ok, chute 3σ (mean ± 3 std) inside ±2.5 km downrange and
    crossrange, switch speed and altitude within 10 % of the paper's 7350 m/s and 78.66 km.

    1000 runs with --paper-scale; 100 in CI (a 3σ interval of 100 runs is looser but the
    limits are 2.5× the 1000-run result)."""
    runs = 1000 if paper_scale else 100
    # CI: in chunks of four on every device, the program tests/test_family.py compiles
    chunk = None if paper_scale else 4
    s = gj.run_study(capsule_scenario, runs=runs, seed=0, chunk_size=chunk, progress=False)
    s = s.summary()
    assert s["failed"] == 0 and s["runs"] == runs
    for name in ("downrange_err_km", "crossrange_err_km"):
        lo, hi = s[name]["three_sigma"]
        assert -2.5 <= lo and hi <= 2.5, (name, lo, hi)
    assert abs(s["switch_speed_mps_mean"] / 7350.0 - 1.0) < 0.10
    assert abs(s["switch_altitude_km_mean"] / 78.66 - 1.0) < 0.10


def test_the_tuners_reverse_mode_traces_on_every_device_count(paper_scale):
    """The tuner's reverse-mode objective of the capsule (the flight's checkpointed
    ``while_loop``, which equinox cannot differentiate inside ``shard_map``) is traced through
    ``jax.grad`` with the test processes' two host devices: its batches run on one device.
    (The pass that differentiates the corrector's solutions, which the tuner leaves out for
    the tracking gains, is traced with --paper-scale.)"""
    from relaxed_gradient import relaxed_objective

    f, problem, theta = relaxed_objective(
        "lunar-skip-entry", "capsule", ["guidance.skip_entry.k_range"]
    )
    assert problem.n_dev == len(jax.devices()) and problem.reverse_fn is not problem.fn
    tuners = problem.args_for("reverse")
    assert not tuners[0].corrector_derivative
    any_ = (problem.system.reverse_mode(problem.sim),) + problem.args[1:]
    for args in (tuners, any_) if paper_scale else (tuners,):
        grad = jax.grad(lambda th, args=args: f(args, th, "reverse"))
        assert jax.eval_shape(grad, theta).shape == theta.shape
