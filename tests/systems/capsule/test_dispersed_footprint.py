"""Each Monte Carlo run's own reachable footprint (the pre-check
columns ``reachable_fraction`` ...), against independent references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import gnc_jax as gj
from gnc_jax import operating_envelope as envelope_module
from gnc_jax.dynamics.entry import EntryState, entry_state_from_conditions
from gnc_jax.guidance.entry import cache, corridor, design
from gnc_jax.guidance.entry.base import EntryModel, flight_variables
from gnc_jax.guidance.entry.corridor import (
    DT_S,
    FOOTPRINT_BANKS_DEG,
    fly_from_state,
    track_footprint,
)
from gnc_jax.montecarlo import run_key
from gnc_jax.systems.capsule import envelope as capsule_envelope
from gnc_jax.systems.capsule import simulation as capsule_sim

SHORT = ["simulation.max_time_s=2000.0"]  # the horizon of tests/test_envelope.py
# every dispersion of the capsule off (its scenario schema lists them)
ZERO = [f"dispersions.{k}=0.0" for k in gj.get_system("capsule").schema()["dispersions"]]


@pytest.fixture
def no_design(monkeypatch, tmp_path):
    """An empty reference cache, and a reference design that fails the test if reached."""
    monkeypatch.setenv("GNC_JAX_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "_MEMORY", {})
    monkeypatch.setattr(design, "design", lambda *a, **k: pytest.fail("reference design ran"))


def _track_range_km(u, start, azimuth, r_e_km):
    """Along-track range by spherical Pythagoras, cos d = cos a cos c (d: great circle from
    the start, c: the crossrange angle off the track): independent of the code's atan2 form."""
    z = np.array([0.0, 0.0, 1.0])
    east = np.cross(z, start)
    east /= np.linalg.norm(east)
    north = np.cross(start, east)
    heading = np.cos(azimuth) * north + np.sin(azimuth) * east
    n = np.cross(start, heading)
    c = np.arcsin(np.dot(u, n))
    d = np.arctan2(np.linalg.norm(np.cross(start, u)), np.dot(start, u))
    return r_e_km * np.arccos(np.clip(np.cos(d) / np.cos(c), -1.0, 1.0))


def _run(sim, seed, i):
    """Run i's dispersed entry, from the key rule of gnc_jax.montecarlo's docstring."""
    key = jax.random.fold_in(jax.random.key(np.uint32(seed)), i)
    y0, vehicle, atmosphere, _ = capsule_sim.dispersed_entry(sim, key)
    return EntryModel(vehicle, sim.earth, atmosphere), y0


def test_zero_dispersions_give_the_nominal_footprint_in_every_run(no_design):
    """Without dispersions every run flies the nominal vehicle from the nominal entry: its
    footprint is the nominal one's flights (the same banks and landing-edge bisection),
    ranges taken along the track instead of the great circle from the entry point: equal
    to the nominal footprint's within the crossrange the Earth's rotation puts on the chute
    point (1e-6 for the shortest, 1 % for the lofted longest), and exactly the along-track
    ranges of the nominal full-lift-down and landing-edge flights."""
    sc = gj.load_scenario("lunar-skip-entry", overrides=SHORT + ZERO)
    fpa = sc.config["entry"]["fpa_deg"]
    fp = capsule_envelope.dispersed_footprints(sc.config, 3, seed=5)
    assert np.all(fp == fp[0])  # every run the same
    env = capsule_envelope.entry_envelope(sc.config)
    lo, hi = env.footprint(fpa)
    assert fp[0, 0] == pytest.approx(lo, rel=1e-6) and fp[0, 1] == pytest.approx(hi, rel=1e-2)
    f = env.flights([fpa], FOOTPRINT_BANKS_DEG)
    assert f.landed[0, -1]  # the shortest: full lift down
    k = int(np.argmax(f.landed[0]))
    assert k > 0  # the longest: the landing edge between banks k - 1 and k
    edge = corridor._landing_edge(
        env.model,
        env.entry,
        jnp.radians(jnp.array([fpa])),
        jnp.radians(jnp.array([FOOTPRINT_BANKS_DEG[k - 1]])),
        jnp.radians(jnp.array([FOOTPRINT_BANKS_DEG[k]])),
        env.chute_m,
        env.steps,
    )
    start = np.array(entry_state_from_conditions(env.entry, env.model.earth).r)
    start /= np.linalg.norm(start)
    az = float(env.entry.azimuth)
    ref_lo = _track_range_km(f.chute_unit[0, -1], start, az, 6378.137)
    ref_hi = _track_range_km(np.asarray(edge.chute_unit[0]), start, az, 6378.137)
    assert fp[0, 0] == pytest.approx(ref_lo, abs=1e-6)
    assert fp[0, 1] == pytest.approx(ref_hi, abs=1e-6)


def test_runs_fly_the_studys_draws():
    """Run i's footprint is the one of the dispersed entry of the study's run i (key
    fold_in(key(seed), i)); the draws differ between runs."""
    sc = gj.load_scenario("lunar-skip-entry", overrides=SHORT)
    sim = capsule_sim.build(sc)
    fp = capsule_envelope.dispersed_footprints(sc.config, 3, seed=7)
    start = np.array(entry_state_from_conditions(sim.entry, sim.earth).r)
    unit_start = start / np.linalg.norm(start)
    for i in range(3):
        model, y0 = _run(sim, 7, i)
        one = track_footprint(
            model, y0, unit_start, sim.entry.azimuth, sim.chute_altitude_m, env_steps(sc)
        )
        np.testing.assert_allclose(fp[i], np.asarray(one) / 1e3, rtol=1e-12)
    assert len({float(x) for x in fp[:, 0]}) == 3
    # and the simulator's own draw for run 1 is that state
    y_sim, *_ = capsule_sim.dispersed_entry(sim, run_key(7, 1))
    np.testing.assert_array_equal(np.asarray(y_sim.r), np.asarray(_run(sim, 7, 1)[1].r))


def env_steps(sc):
    return int(np.ceil(sc.config["simulation"]["max_time_s"] / DT_S))


def test_a_dispersed_runs_shortest_range_matches_scipy():
    """Run 2's shortest range is its full-lift-down flight's, and that flight of its own
    dispersed vehicle, atmosphere and entry state matches scipy's DOP853 on the same field
    within 2 km along the nominal track (the 2 s RK4 step, the crossing at the step's end)."""
    sc = gj.load_scenario("lunar-skip-entry", overrides=SHORT)
    sim = capsule_sim.build(sc)
    model, y0 = _run(sim, 0, 2)
    fp = capsule_envelope.dispersed_footprints(sc.config, 3, seed=0)[2]
    steps = env_steps(sc)
    down = fly_from_state(model, y0, np.pi, sim.chute_altitude_m, steps)
    start = np.array(entry_state_from_conditions(sim.entry, sim.earth).r)
    start /= np.linalg.norm(start)
    az, r_e_km = float(sim.entry.azimuth), float(sim.earth.equatorial_radius_m) / 1e3
    assert bool(down.landed)
    assert fp[0] == pytest.approx(_track_range_km(np.asarray(down.chute_unit), start, az, r_e_km))

    @jax.jit
    def field(x):
        y = EntryState(x[:3], x[3:])
        d = model.vertical_plane_field(0.0, y, -1.0)
        return jnp.concatenate([d.r, d.v]), flight_variables(y, sim.earth).altitude_m

    def chute(t, x):
        return float(field(x)[1]) - float(sim.chute_altitude_m)

    chute.terminal, chute.direction = True, -1
    x0 = np.concatenate([np.asarray(y0.r), np.asarray(y0.v)])
    sol = solve_ivp(
        lambda t, x: np.asarray(field(x)[0]),
        (0, steps * DT_S),
        x0,
        "DOP853",
        rtol=1e-8,
        atol=1e-3,
        events=chute,
    )
    assert sol.t_events[0].size == 1
    t_c, r_c = sol.t_events[0][0], sol.y_events[0][0][:3]
    w = float(sim.earth.rotation_rate) * t_c
    u = np.array(
        [np.cos(w) * r_c[0] + np.sin(w) * r_c[1], -np.sin(w) * r_c[0] + np.cos(w) * r_c[1], r_c[2]]
    )
    ref = _track_range_km(u / np.linalg.norm(u), start, az, r_e_km)
    assert abs(fp[0] - ref) < 2.0


def test_reachability_counts_and_quantiles():
    """Fractions by counting, the dispersed ends by sorting: 200 runs, one that never lands."""
    rng = np.random.default_rng(3)
    lo = rng.uniform(1000, 3000, 200)
    hi = rng.uniform(9000, 12000, 200)
    fp = np.stack([lo, hi], axis=1)
    fp[17] = np.nan
    r = capsule_envelope.reachability(fp, 9500.0)
    assert r["reachable_fraction"] == np.sum(hi[np.arange(200) != 17] >= 9500.0) / 200
    w = hi - lo
    m = (lo + 0.1 * w <= 9500.0) & (9500.0 <= hi - 0.1 * w)
    m[17] = False
    assert r["reachable_fraction_margin"] == m.sum() / 200
    assert r["no_landing_fraction"] == pytest.approx(1 / 200, rel=1e-12)
    # the dispersed ends: all but one run (0.5 % of 200) reach them; the one that lands
    # nowhere is that run, so the ends are the extremes of the others
    assert r["dispersed_footprint_min_km"] == np.delete(lo, 17).max()
    assert r["dispersed_footprint_max_km"] == np.delete(hi, 17).min()
    r = capsule_envelope.reachability(np.stack([lo, hi], axis=1), 9500.0)  # all land: one
    assert r["dispersed_footprint_min_km"] == np.sort(lo)[-2]  # run beyond each end
    assert r["dispersed_footprint_max_km"] == np.sort(hi)[1]
    fp[18] = np.nan  # two runs that land nowhere: more than 0.5 % reach nothing
    r = capsule_envelope.reachability(fp, 9500.0)
    assert np.isnan(r["dispersed_footprint_min_km"]) and np.isnan(r["dispersed_footprint_max_km"])


def test_envelope_pre_check_columns_without_a_design(monkeypatch, no_design):
    """The envelope passes its runs and seed to the pre-check; a feasible cell's columns are
    those of its runs' footprints, computed once per angle for every range; no reference
    design; the heat map's overlay draws the dispersed footprint."""
    monkeypatch.setattr(envelope_module, "run_study", lambda *a, **k: pytest.fail("ran"))
    sc = gj.load_scenario("lunar-skip-entry", overrides=SHORT)
    system = sc.system
    cfgs = [sc.with_overrides({"entry.range_km": r}).config for r in (2500.0, 8000.0)]
    checks = system.envelope_check(cfgs, runs=3, seed=7)
    fp = capsule_envelope.dispersed_footprints(cfgs[0], 3, seed=7)
    for check, r in zip(checks, (2500.0, 8000.0)):
        cols = check["columns"]
        assert check["feasible"] and cols["footprint_runs"] == 3
        for k, v in capsule_envelope.reachability(fp, r).items():
            assert cols[k] == v or (np.isnan(cols[k]) and np.isnan(v))
    assert checks[0]["columns"]["footprint_s"] == checks[1]["columns"]["footprint_s"]
    seen = {}
    monkeypatch.setattr(
        type(system),
        "envelope_check",
        lambda self, configs, **kw: seen.update(kw) or [{"feasible": False}] * len(configs),
    )
    gj.envelope(sc, {"entry.range_km": [8000.0]}, runs=5, seed=11, progress=False)
    assert seen == {"runs": 5, "seed": 11}

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ends = {-6.0: (3000.0, 7000.0), -5.8: (3500.0, 9000.0)}
    cells = [
        {
            "entry.fpa_deg": a,
            "entry.range_km": r,
            "load_limit_g": 10.0,
            "dispersed_footprint_min_km": ends[a][0],
            "dispersed_footprint_max_km": ends[a][1],
        }
        for a in ends
        for r in (2500.0, 8000.0)
    ]
    env = envelope_module.Envelope(
        sc, {"entry.fpa_deg": [-6.0, -5.8], "entry.range_km": [2500.0, 8000.0]}, cells, {}, 3, 7
    )
    fig, ax = plt.subplots()
    ax.set_ylim(0, 20000)
    system.envelope_overlay(ax, env, "entry.fpa_deg", "entry.range_km")
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    plt.close(fig)
    longest = [
        v for k, v in lines.items() if k.startswith("dispersed footprint") and "longest" in k
    ]
    assert len(longest) == 1
    np.testing.assert_array_equal(longest[0].get_xdata(), [-6.0, -5.8])
    np.testing.assert_array_equal(longest[0].get_ydata(), [7000.0, 9000.0])
