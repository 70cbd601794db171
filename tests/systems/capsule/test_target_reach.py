"""Whether a run can reach the target itself, downrange and crossrange (three-dimensional
constant-magnitude flights with one reversal), against independent references."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import gnc_jax as gj
from gnc_jax.dynamics.entry import (
    EntryArgs,
    EntryState,
    entry_state_from_conditions,
)
from gnc_jax.dynamics.entry.forces import entry_vector_field
from gnc_jax.geometry.sphere import along_cross_track, to_earth_fixed, unit
from gnc_jax.guidance.entry import corridor
from gnc_jax.guidance.entry.base import EntryModel, flight_variables
from gnc_jax.guidance.entry.corridor import (
    DT_S,
    fly_from_state,
    grid_crossings,
    target_crossrange_span,
)
from gnc_jax.systems.capsule import envelope as capsule_envelope
from gnc_jax.systems.capsule import simulation as capsule_sim

STEPS = 1200  # the packaged horizon, 2400 s


@pytest.fixture(scope="module")
def coarse():
    """A coarse family (CI-sized): magnitudes every 10 deg, reversals at 0, 100, 200 s, none
    (read when the flights are traced: the compiled family is dropped before and after)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(corridor, "REACH_BANKS_DEG", np.arange(0.0, 180.0 + 1e-9, 10.0))
        mp.setattr(corridor, "REACH_REVERSALS_S", np.array([0.0, 100.0, 200.0, np.inf]))
        target_crossrange_span.clear_cache()
        yield
    target_crossrange_span.clear_cache()


def _nominal():
    sc = gj.load_scenario("lunar-skip-entry")
    sim = capsule_sim.build(sc)
    model = EntryModel(sim.vehicle, sim.earth, sim.atmosphere)
    y0 = entry_state_from_conditions(sim.entry, sim.earth)
    return sc, sim, model, y0


def test_grid_crossings_are_the_brute_force_zero_crossings():
    """Chute points placed at known (along, cross) angles: the crossings are the crossranges
    linearly interpolated at every sign change of the along error between neighbouring
    magnitudes that both land, found by a plain loop."""
    rng = np.random.default_rng(4)
    along = rng.uniform(-0.05, 0.05, (2, 3, 12))
    cross = rng.uniform(-0.02, 0.02, (2, 3, 12))
    landed = rng.uniform(size=(2, 3, 12)) > 0.2
    hit, c = map(np.asarray, grid_crossings(jnp.asarray(landed), along, cross))
    found = []
    for f in np.ndindex(2, 3):
        a, x, ok = along[f], cross[f], landed[f]
        for k in range(11):
            if ok[k] and ok[k + 1] and a[k] * a[k + 1] <= 0 and a[k] != a[k + 1]:
                w = a[k] / (a[k] - a[k + 1])
                found.append(x[k] + w * (x[k + 1] - x[k]))
    assert len(found) > 2
    np.testing.assert_allclose(np.sort(c[hit]), np.sort(found), rtol=1e-12)


def test_full_lift_down_in_three_dimensions_is_the_vertical_plane_flight():
    """Full lift down has no lateral component: the three-dimensional flight at bank pi
    lands where the vertical-plane flight at bank pi does."""
    _, sim, model, y0 = _nominal()
    a = fly_from_state(model, y0, np.pi, sim.chute_altitude_m, STEPS)
    b = fly_from_state(model, y0, np.pi, sim.chute_altitude_m, STEPS, lateral=True)
    assert bool(a.landed) and bool(b.landed)
    np.testing.assert_allclose(np.asarray(b.chute_unit), np.asarray(a.chute_unit), atol=1e-9)


def test_banked_flight_matches_scipy_and_turns_with_the_bank():
    """A bank of +90 deg reversed at 150 s, against scipy's DOP853 on the simulator's truth
    field (``entry_vector_field``) with the same reversal: the chute point within 2 km
    along and across the track (the 2 s RK4 step, the crossing at the step's end); a
    positive bank first ends to the right of where the negative one ends."""
    _, sim, model, y0 = _nominal()
    start = unit(y0.r)
    tau, bank = 150.0, np.radians(90.0)
    flights = [
        fly_from_state(model, y0, s * bank, sim.chute_altitude_m, STEPS, True, tau)
        for s in (1.0, -1.0)
    ]
    r_e_km = float(sim.earth.equatorial_radius_m) / 1e3
    right, left = (
        np.asarray(along_cross_track(f.chute_unit, start, sim.target_fixed)) * r_e_km
        for f in flights
    )
    assert all(bool(f.landed) for f in flights) and right[1] < left[1] - 20.0

    @jax.jit
    def field(x, b):
        y = EntryState(x[:3], x[3:])
        d = entry_vector_field(0.0, y, EntryArgs(sim.vehicle, sim.earth, sim.atmosphere, b))
        return jnp.concatenate([d.r, d.v]), flight_variables(y, sim.earth).altitude_m

    def chute(t, x):
        return float(field(x, 0.0)[1]) - float(sim.chute_altitude_m)

    chute.terminal, chute.direction = True, -1
    x = np.concatenate([np.asarray(y0.r), np.asarray(y0.v)])
    opts = dict(rtol=1e-9, atol=1e-4)
    first = solve_ivp(lambda t, x: np.asarray(field(x, bank)[0]), (0, tau), x, "DOP853", **opts)
    rest = solve_ivp(
        lambda t, x: np.asarray(field(x, -bank)[0]),
        (tau, STEPS * DT_S),
        first.y[:, -1],
        "DOP853",
        events=chute,
        **opts,
    )
    assert rest.t_events[0].size == 1
    t_c, r_c = rest.t_events[0][0], rest.y_events[0][0][:3]
    u = np.asarray(to_earth_fixed(jnp.asarray(r_c), t_c, sim.earth.rotation_rate))
    ref = np.asarray(along_cross_track(unit(jnp.asarray(u)), start, sim.target_fixed)) * r_e_km
    np.testing.assert_allclose(right, ref, atol=2.0)


def test_the_nominal_vehicle_reaches_its_target_and_not_one_far_aside(coarse):
    """The packaged capsule's own flights hold its target (8000 km, reached only by a lofted
    skip: the landing-edge crossing) in their crossrange span, as the law lands there; a
    target 1500 km to the left of the track, beyond what an L/D 0.3 capsule can turn, is
    not."""
    _, sim, model, y0 = _nominal()
    start = unit(y0.r)
    args = (sim.chute_altitude_m, STEPS)
    span = np.asarray(target_crossrange_span(model, y0, start, sim.target_fixed, *args))
    assert span[0] < 0.0 < span[1]
    left = unit(jnp.cross(start, sim.target_fixed))  # the track's left at the target
    d = 1500e3 / sim.earth.equatorial_radius_m
    aside = jnp.cos(d) * sim.target_fixed + jnp.sin(d) * left
    far = np.asarray(target_crossrange_span(model, y0, start, aside, *args))
    assert not far[0] <= 0.0 <= far[1]


def test_target_reach_flies_each_runs_own_draws(coarse):
    """Run i is flown from the study's own dispersed entry, vehicle and atmosphere (key
    fold_in(key(seed), i), the rule of gnc_jax.montecarlo's docstring); runs differ."""
    sc = gj.load_scenario("lunar-skip-entry")
    spans = capsule_envelope.target_reach(sc.config, [0, 3], seed=1)
    sim = capsule_sim.build(sc)
    key = jax.random.fold_in(jax.random.key(np.uint32(1)), 3)
    y0, vehicle, atmosphere, _ = capsule_sim.dispersed_entry(sim, key)
    model = EntryModel(vehicle, sim.earth, atmosphere)
    start = unit(entry_state_from_conditions(sim.entry, sim.earth).r)
    one = target_crossrange_span(model, y0, start, sim.target_fixed, sim.chute_altitude_m, STEPS)
    np.testing.assert_allclose(spans[1], np.asarray(one) / 1e3, rtol=1e-12)
    assert not np.allclose(spans[0], spans[1])
