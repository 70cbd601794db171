"""``gnc-jax envelope`` and its capsule pre-check."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.integrate import solve_ivp

import gnc_jax as gj
from gnc_jax import cli
from gnc_jax import operating_envelope as envelope_module
from gnc_jax.dynamics.entry import EntryState, entry_state_from_conditions
from gnc_jax.guidance.entry.base import flight_variables
from gnc_jax.guidance.entry.corridor import DT_S, fly_constant_bank
from gnc_jax.planner import CostEstimate
from gnc_jax.systems.capsule.envelope import entry_envelope
from gnc_jax.systems.impactor.system import ImpactorSystem


def test_grid_specs_parse_and_bad_ones_name_the_axis():
    assert envelope_module.parse_grid("entry.fpa_deg=-6:-5:3") == (
        "entry.fpa_deg",
        [-6.0, -5.5, -5.0],
    )
    assert envelope_module.parse_grid("entry.range_km=2500,5000") == (
        "entry.range_km",
        [2500.0, 5000.0],
    )
    for bad in ("entry.fpa_deg=-6:-5", "entry.fpa_deg=-6:-5:0", "fpa=1:2:3", "entry.fpa_deg"):
        with pytest.raises(gj.ScenarioError, match="--grid"):
            envelope_module.parse_grid(bad)


@pytest.mark.parametrize(
    "grid,kw,message",
    [
        ({"guidance.los.k1": 3.0}, {}, "grid: guidance.los.k1 = 3.0; allowed: a non-empty list"),
        ({"guidance.los.k1": []}, {}, "grid: guidance.los.k1 = []; allowed: a non-empty list"),
        (["guidance.los.k1=2:3:1"], {}, "one value cannot span 2 .. 3; allowed: n >= 2"),
        (["guidance.los.k1=2,3"], dict(seed=-1), "seed: -1; allowed: an integer in [0, 2^32)"),
    ],
)
def test_a_bad_grid_or_seed_is_refused_before_any_cell(grid, kw, message, monkeypatch):
    monkeypatch.setattr(envelope_module, "run_study", lambda *a, **k: pytest.fail("ran"))
    monkeypatch.setattr(envelope_module, "estimate_cost", lambda *a, **k: pytest.fail("costed"))
    scenario = gj.load_scenario("deep-impact-los")
    with pytest.raises(gj.ScenarioError) as e:
        envelope_module.envelope(scenario, grid, runs=2, progress=False, **kw)
    assert message in str(e.value)


def test_a_grid_value_outside_the_field_range_is_refused_before_any_study(capsys, monkeypatch):
    monkeypatch.setattr(envelope_module, "run_study", lambda *a, **k: pytest.fail("ran"))
    argv = ["envelope", "lunar-skip-entry", "--grid", "entry.fpa_deg=-20:-5:3", "--out", "/tmp/x"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("gnc-jax: error: entry.fpa_deg: -20")


def test_a_field_on_two_axes_is_refused_in_one_line(capsys, tmp_path):
    argv = ["envelope", "deep-impact-los", "--grid", "guidance.los.k1=3:5:3"]
    argv += ["--grid", "guidance.los.k1=1,2", "--out", str(tmp_path)]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "gnc-jax: error: --grid guidance.los.k1=1,2: guidance.los.k1 is already an axis; "
        "allowed: each field on one --grid (its values as a:b:n or v1,v2,...)"
    )


class _Ran(Exception):
    pass


def _no_study(*args, **kwargs):
    raise _Ran


def test_an_envelope_over_its_cost_is_refused_before_any_study(monkeypatch):
    """The estimate is each cell's study estimate (computed here cell by cell) plus the
    per-cell overhead: refused just below it, run just above it; a grid of more than
    COST_SAMPLE cells is costed from that many; one whose cells alone exceed the bound is
    refused before any cell is built."""
    monkeypatch.setattr(envelope_module, "run_study", _no_study)
    sc = gj.load_scenario("deep-impact-los", ImpactorSystem.test_overrides)
    axes = {"guidance.los.k1": [3.0, 4.0, 5.0], "spacecraft.mass_kg": [300.0, 372.0, 450.0]}
    runs = 500
    cells = [
        sc.with_overrides({"guidance.los.k1": k1, "spacecraft.mass_kg": m})
        for k1, m in itertools.product(*axes.values())
    ]
    hours = (
        sum(gj.estimate_cost(c, runs).seconds for c in cells)
        + len(cells) * envelope_module.CELL_OVERHEAD_S
    ) / 3600
    with pytest.raises(gj.ScenarioError, match=r"^cost: 9 cells of 500 runs, about .*; allowed"):
        gj.envelope(sc, axes, runs=runs, progress=False, max_hours=0.999 * hours)
    with pytest.raises(_Ran):
        gj.envelope(sc, axes, runs=runs, progress=False, max_hours=1.001 * hours)

    costed = []

    def cost(scenario, runs, device=None):
        costed.append(scenario)
        return CostEstimate(runs, 1.0, 1, 1.0)

    monkeypatch.setattr(envelope_module, "estimate_cost", cost)
    big = {"guidance.los.k1": list(np.linspace(3, 5, 100)), "guidance.dt_s": [0.5] * 100}
    with pytest.raises(gj.ScenarioError, match=r"^cost: 10000 cells of 2 runs, about 3 h \(2.8 h"):
        gj.envelope(sc, big, runs=2, progress=False, max_hours=2.0)
    assert len(costed) == envelope_module.COST_SAMPLE

    monkeypatch.setattr(envelope_module, "_cell_scenarios", _no_study)
    huge = {"guidance.los.k1": [4.0] * 2000, "guidance.los.k2": [1.0] * 100}
    with pytest.raises(gj.ScenarioError, match=r"^cost: 200000 cells, more than 3.9 h at"):
        gj.envelope(sc, huge, runs=2, progress=False, max_hours=2.0)
    assert len(costed) == envelope_module.COST_SAMPLE  # no cell built


@pytest.mark.parametrize(
    "grid,message",
    [
        (
            ["guidance.los.k1=3:5:1000000000"],
            "--grid guidance.los.k1=3:5:1000000000: 1000000000 values; allowed: at most "
            "1234285 values on an axis",
        ),
        (
            [f"{k}=1:2:10000" for k in ("guidance.los.k1", "guidance.los.k2", "guidance.dt_s")],
            "--grid: guidance.los.k1 10000 x guidance.los.k2 10000 x guidance.dt_s 10000 = "
            "1000000000000 cells; allowed: at most 1234285 cells",
        ),
        (
            {"guidance.los.k1": [4.0] * 2000, "guidance.los.k2": [1.0] * 1000},
            "grid: guidance.los.k1 2000 x guidance.los.k2 1000 = 2000000 cells; allowed",
        ),
    ],
)
def test_a_grid_over_max_cells_is_refused_before_its_values_are_made(grid, message, monkeypatch):
    """MAX_CELLS is the grid whose per-cell overhead alone fills the default MAX_HOURS; a
    larger axis or grid is refused whatever max_hours, before linspace or any cell."""
    assert envelope_module.MAX_CELLS * envelope_module.CELL_OVERHEAD_S <= 24 * 3600
    assert (envelope_module.MAX_CELLS + 1) * envelope_module.CELL_OVERHEAD_S > 24 * 3600
    linspace = np.linspace

    def small_linspace(a, b, n):
        assert n <= envelope_module.MAX_CELLS, "made"
        return linspace(a, b, n)

    monkeypatch.setattr(np, "linspace", small_linspace)
    monkeypatch.setattr(envelope_module, "_cell_scenarios", _no_study)
    monkeypatch.setattr(envelope_module, "estimate_cost", lambda *a, **k: pytest.fail("costed"))
    scenario = gj.load_scenario("deep-impact-los")
    with pytest.raises(gj.ScenarioError) as e:
        gj.envelope(scenario, grid, runs=2, progress=False, max_hours=1e12)
    assert message in str(e.value)


def test_cells_are_the_studies_of_their_scenarios(tmp_path):
    """Each cell's metrics are those of run_study on the scenario with the cell's values."""
    sc = gj.load_scenario("deep-impact-los", ImpactorSystem.test_overrides)
    env = gj.envelope(sc, ["guidance.los.k1=3:5:2"], runs=4, seed=2, out=tmp_path, progress=False)
    table = pq.read_table(tmp_path / "cells.parquet").to_pydict()
    assert table["guidance.los.k1"] == [3.0, 5.0]
    s = gj.run_study(sc.with_overrides({"guidance.los.k1": 5.0}), runs=4, seed=2).summary()
    assert table["miss_rms_m"][1] == pytest.approx(s["miss_rms_m"], rel=1e-12)
    assert table["dv_mean_mps"][1] == pytest.approx(s["dv_mean_mps"], rel=1e-12)
    assert table["miss_rms_m"][0] != table["miss_rms_m"][1]  # the cells differ by their k1
    assert {p.name for p in tmp_path.iterdir()} >= {
        "cells.parquet",
        "envelope_hit_probability.png",
        "envelope_dv_mean_mps.png",
    }
    assert all(c["status"] == "simulated" for c in env.cells)


SHORT_CAPSULE = ["simulation.max_time_s=2000.0"]


def test_constant_bank_flight_matches_scipy():
    """The open-loop flight against scipy's DOP853 on the same vertical-plane field: chute
    range within 2 km (the 2 s RK4 step and the crossing taken at the step's end) and peak
    load within 1 %."""
    sc = gj.load_scenario("lunar-skip-entry", overrides=SHORT_CAPSULE)
    env = entry_envelope(sc.config)
    bank = np.radians(100.0)
    f = fly_constant_bank(env.model, env.entry, bank, env.chute_m, env.steps)
    earth = env.model.earth
    y0 = entry_state_from_conditions(env.entry, earth)

    @jax.jit
    def field(x):
        d = env.model.vertical_plane_field(0.0, EntryState(x[:3], x[3:]), np.cos(bank))
        alt = flight_variables(EntryState(x[:3], x[3:]), earth).altitude_m
        return jnp.concatenate([d.r, d.v]), alt, env.model.load_g(EntryState(x[:3], x[3:]))

    def rhs(t, x):
        return np.asarray(field(x)[0])

    def chute(t, x):
        return float(field(x)[1]) - env.chute_m

    chute.terminal, chute.direction = True, -1
    x0 = np.concatenate([np.asarray(y0.r), np.asarray(y0.v)])
    sol = solve_ivp(
        rhs,
        (0, env.steps * DT_S),
        x0,
        "DOP853",
        rtol=1e-8,
        atol=1e-3,
        events=chute,
        dense_output=True,
    )
    assert bool(f.landed) and sol.t_events[0].size == 1
    t_c = sol.t_events[0][0]
    from gnc_jax.guidance.entry.base import ground_range_m

    ref_range = float(ground_range_m(y0.r, 0.0, sol.y_events[0][0][:3], t_c, earth))
    assert abs(float(f.range_m) - ref_range) < 2e3
    ts = np.linspace(0, t_c, 3000)
    loads = [float(field(x)[2]) for x in sol.sol(ts).T]
    assert float(f.peak_load_g) == pytest.approx(max(loads), rel=0.01)


def test_cells_outside_the_corridor_are_not_simulated(monkeypatch):
    """A shallow angle that skips out with full lift down and a steep one beyond the load
    limit with full lift up are infeasible before anything runs; the pre-check's verdict is
    the open-loop flights' own at those angles, at the scenario's simulation.load_limit_g."""
    monkeypatch.setattr(envelope_module, "run_study", lambda *a, **k: pytest.fail("ran"))
    sc = gj.load_scenario("lunar-skip-entry", overrides=SHORT_CAPSULE)
    env = gj.envelope(sc, {"entry.fpa_deg": [-9.0, -4.5]}, runs=2, progress=False)
    assert [c["status"] for c in env.cells] == ["infeasible", "infeasible"]
    assert "undershoot" in env.cells[0]["reason"] and "overshoot" in env.cells[1]["reason"]
    lo, hi = env.cells[0]["corridor_undershoot_deg"], env.cells[0]["corridor_overshoot_deg"]
    assert -9.0 < lo < hi < -4.5
    flights = entry_envelope(sc.config).flights([lo, hi, hi + 0.05], [180.0, 0.0])
    assert flights.peak_load_g[0, 1] <= 10.0 and flights.landed[1, 0]
    assert not flights.landed[2, 0]
    # the undershoot boundary is the scenario's own load limit, the one its runs are held to
    tight = sc.with_overrides(["simulation.load_limit_g=8"])
    env = gj.envelope(tight, {"entry.fpa_deg": [-9.0]}, runs=2, progress=False)
    lo_8 = env.cells[0]["corridor_undershoot_deg"]
    assert env.cells[0]["load_limit_g"] == 8.0 and lo < lo_8 < hi
    flights = entry_envelope(tight.config).flights([lo_8, lo_8 - 0.05], [0.0])
    assert flights.peak_load_g[0, 0] <= 8.0 < flights.peak_load_g[1, 0]
