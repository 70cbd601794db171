"""The direct-entry mode of the capsule law: its design against scipy, the mode choice from
the reach, the refusals, and a closed-loop flight."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import gnc_jax as gj
from gnc_jax.dynamics.entry import EntryState, entry_state_from_conditions
from gnc_jax.guidance.entry import direct
from gnc_jax.guidance.entry.base import flight_variables
from gnc_jax.schema import ScenarioError
from gnc_jax.systems.capsule import simulation as capsule_sim
from gnc_jax.systems.capsule.reference import (
    direct_load_limit_g,
    law_mission,
    mode_reference,
    nominal_problem,
)

# every dispersion of the capsule off (its scenario schema lists them)
ZERO = [f"dispersions.{k}=0.0" for k in gj.get_system("capsule").schema()["dispersions"]]


def _setup(range_km, overrides=()):
    sc = gj.load_scenario("lunar-skip-entry", overrides=[f"entry.range_km={range_km}", *overrides])
    sim = capsule_sim.build(sc)
    return sc, sim, nominal_problem(sc.config, sim, 0.2)


def _law_load_limit_g(sc) -> float:
    """The load limit of a direct landing: the smaller of the capsule's and the law's
    prediction limit."""
    law = gj.get_system("capsule").laws()["skip_entry"]
    predicted = law.predicted_load_limit_g(sc.config["guidance"]["skip_entry"])
    limit = min(predicted, sc.config["simulation"]["load_limit_g"])
    assert direct_load_limit_g(law, sc.config) == limit
    return limit


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
    d = np.arccos(np.clip(np.dot(u, start), -1.0, 1.0))
    return r_e_km * np.arccos(np.clip(np.cos(d) / np.cos(c), -1.0, 1.0))


def test_direct_design_lands_on_target_by_scipy():
    """The designed constant bank, flown by scipy's DOP853 on the same field, puts the chute
    within 2 km of the 2000 km target (the design's 2 s RK4 step) and never climbs above
    the direct-entry apogee."""
    sc, sim, problem = _setup(2000.0)
    bank = direct.design_direct(problem, sc.config["entry"], sc.config["vehicle"])
    model = problem.model

    @jax.jit
    def field(x):
        y = EntryState(x[:3], x[3:])
        d = model.vertical_plane_field(0.0, y, jnp.cos(bank))
        return jnp.concatenate([d.r, d.v]), flight_variables(y, sim.earth).altitude_m

    def chute(t, x):
        return float(field(x)[1]) - float(sim.chute_altitude_m)

    chute.terminal, chute.direction = True, -1
    y0 = entry_state_from_conditions(sim.entry, sim.earth)
    x0 = np.concatenate([np.asarray(y0.r), np.asarray(y0.v)])
    sol = solve_ivp(
        lambda t, x: np.asarray(field(x)[0]),
        (0, 3000.0),
        x0,
        "DOP853",
        rtol=1e-8,
        atol=1e-3,
        events=chute,
        dense_output=True,
    )
    assert sol.t_events[0].size == 1
    t_c, r_c = sol.t_events[0][0], sol.y_events[0][0][:3]
    w = float(sim.earth.rotation_rate) * t_c
    u = np.array(
        [np.cos(w) * r_c[0] + np.sin(w) * r_c[1], -np.sin(w) * r_c[0] + np.cos(w) * r_c[1], r_c[2]]
    )
    start = np.asarray(y0.r) / np.linalg.norm(np.asarray(y0.r))
    r_e_km = float(sim.earth.equatorial_radius_m) / 1e3
    landed_km = _track_range_km(u / np.linalg.norm(u), start, float(sim.entry.azimuth), r_e_km)
    assert abs(landed_km - 2000.0) < 2.0
    # direct: after the lowest point of the dive the flight stays below the apogee limit
    alt = np.linalg.norm(sol.y[:3], axis=0) - float(sim.earth.equatorial_radius_m)
    dip = int(np.argmin(alt[: np.argmax(alt < 40e3) + 200]))
    assert alt[dip:].max() < direct.DIRECT_APOGEE_M + 2e3  # (the ellipsoid's few km)


def test_mode_choice_from_the_reach():
    """'auto' flies a direct entry at 2000 km (inside the direct reach at -5.9 deg) and the
    packaged skip at 8000 km; the direct reach straddles 2000 km and stops short of 8000."""
    sc, sim, problem = _setup(2000.0)
    lo, hi = direct.direct_reach(direct.scan_direct(problem))
    assert lo < 0.0 < hi < 6000e3
    ref, mode = mode_reference(sc.config, sim, 0.2, "auto")
    assert mode == "direct" and float(ref.switch_velocity_mps) == 0.0
    sc, sim, _ = _setup(8000.0)
    ref, mode = mode_reference(sc.config, sim, 0.2, "auto")
    assert mode == "skip" and float(ref.switch_velocity_mps) > 5000.0


def test_refusals_name_the_field_and_the_interval():
    """A direct entry at the packaged 8000 km is refused in one line naming entry.range_km
    with the direct reach; a target short of both modes (800 km) with the skip's interval
    and the direct reach; an unknown entry_mode before any design."""
    sc, sim, problem = _setup(8000.0)
    with pytest.raises(ScenarioError) as e:
        mode_reference(sc.config, sim, 0.2, "direct")
    msg = str(e.value)
    assert msg.startswith("entry.range_km: 8000 km; allowed: ") and "\n" not in msg
    lo, hi = (float(x) for x in re.search(r"allowed: (\d+) \.\. (\d+) km", msg).groups())
    reach = direct.direct_reach(direct.scan_direct(problem))
    assert (lo, hi) == (round(8000 + reach[0] / 1e3), round(8000 + reach[1] / 1e3))
    sc, sim, _ = _setup(800.0)  # short of both: the skip's refusal, with the direct reach
    with pytest.raises(ScenarioError) as e:
        mode_reference(sc.config, sim, 0.2, "auto")
    msg = str(e.value)
    assert msg.startswith("entry.range_km: 800 km") and "\n" not in msg
    assert f"a direct entry reaches {lo:.0f} .. {hi:.0f} km" in msg
    # 1200 km: landed by constant banks steeper than 112 deg, whose loads (up to 45 g) exceed
    # the capsule's 10 g limit and the law's predictions end as dives; the reach starts beyond
    # it, at 90 % of the smaller limit: the capsule's by default, the law's for a capsule
    # allowed more than the law's 20 g
    law = gj.get_system("capsule").laws()["skip_entry"]
    starts = []
    for limit_g, direct_g in ((10.0, 9), (30.0, 18)):
        sc, sim, _ = _setup(
            1200.0,
            ["guidance.skip_entry.entry_mode=direct", f"simulation.load_limit_g={limit_g}"],
        )
        with pytest.raises(ScenarioError) as e:
            law_mission(law, sc.config, sim)
        msg = str(e.value)
        assert msg.startswith("entry.range_km: 1200 km; allowed: ") and "\n" not in msg
        starts.append(float(re.search(r"allowed: (\d+) \.\. ", msg).group(1)))
        assert starts[-1] > 1200.0 and f"loads up to {direct_g} g" in msg
    assert starts[0] > starts[1]
    with pytest.raises(ScenarioError) as e:
        gj.load_scenario("lunar-skip-entry", overrides=["guidance.skip_entry.entry_mode=glide"])
    msg = str(e.value)
    assert "guidance.skip_entry.entry_mode" in msg and "direct" in msg and "\n" not in msg


def test_a_direct_flight_lands_on_target():
    """Two undispersed direct-mode runs at 2000 km: no skip (no switch point), the chute
    within the direct corrector's tolerance of the target; at the short end of the law's
    direct reach, within the delivery tolerance (simulation.miss_limit_km)."""
    sc = gj.load_scenario(
        "lunar-skip-entry", overrides=["entry.range_km=2000", "simulation.max_time_s=1500"] + ZERO
    )
    s = gj.run_study(sc, runs=2, seed=0, progress=False).summary()
    assert s["failed"] == 0 and s["switch_speed_mps_mean"] == 0.0
    assert s["skip_apogee_km_mean"] == 0.0
    assert abs(s["downrange_err_km"]["max"]) < 1.5 and abs(s["downrange_err_km"]["min"]) < 1.5
    problem = _setup(2000.0)[2]
    lo, _ = direct.direct_reach(direct.scan_direct(problem, _law_load_limit_g(sc)))
    short = sc.with_overrides([f"entry.range_km={np.ceil(2000.0 + lo / 1e3):g}"])
    s = gj.run_study(short, runs=2, seed=0, progress=False).summary()
    limit = sc.config["simulation"]["miss_limit_km"]
    assert s["failed"] == 0 and s["switch_speed_mps_mean"] == 0.0
    assert abs(s["downrange_err_km"]["max"]) < limit and abs(s["downrange_err_km"]["min"]) < limit
