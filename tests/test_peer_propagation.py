"""The propagation peers of benchmarks/peers/propagation.py integrate gnc_jax's equations.

numba's hand-written RK4 must reproduce gnc_jax's `integrate_fixed` RK4 run for run (same
states, same step) to rounding, and heyoka's expression-system transcriptions must evaluate
to gnc_jax's vector fields (entry: `entry_vector_field` with the exponential atmosphere;
cruise: `heliocentric.vector_field` with plan94 evaluated directly), so that the benchmark
compares integrators on the same equations. heyoka is in the ``test`` extra (numba arrives with
lamberthub), so these tests run wherever the suite does.
"""

import importlib.util
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnc_jax  # noqa: F401  (float64)
from gnc_jax.dynamics import ephemeris
from gnc_jax.dynamics.entry import EntryArgs, EntryState, entry_vector_field
from gnc_jax.dynamics.heliocentric import HeliocentricModel, vector_field
from gnc_jax.integrate import integrate_fixed

_PATH = pathlib.Path(__file__).parents[1] / "benchmarks" / "peers" / "propagation.py"


@pytest.fixture(scope="module")
def peers():
    spec = importlib.util.spec_from_file_location("peer_propagation", _PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def entry(peers):
    return peers.entry_ensemble(6, seed=3)


DT_S, STEPS, LEGS = 2.0, 50, 8  # one compiled RK4 leg of 100 s, chained over the 800 s arc


@pytest.fixture(scope="module")
def gnc_legs(entry):
    """gnc_jax RK4 states after 1..8 legs: through the first dip (~100 s) and the skip."""

    def leg(y, item):
        _, vehicle, atmosphere, bank = item
        args = EntryArgs(vehicle, entry.earth, atmosphere, bank)
        return integrate_fixed(entry_vector_field, 0.0, y, DT_S, STEPS, args)

    leg = jax.jit(jax.vmap(leg))
    y, out = entry.y0, []
    for _ in range(LEGS):
        y = leg(y, entry.batch)
        out.append(np.concatenate([np.asarray(y.r), np.asarray(y.v)], axis=1))
    return out


def _gnc_field(entry, states):
    def field(r, v, item):
        _, vehicle, atmosphere, bank = item
        d = entry_vector_field(
            0.0, EntryState(r, v), EntryArgs(vehicle, entry.earth, atmosphere, bank)
        )
        return jnp.concatenate([d.r, d.v])

    return np.asarray(jax.vmap(field)(states[:, :3], states[:, 3:], entry.batch))


def test_numba_rk4_equals_gnc_jax_rk4(peers, entry, gnc_legs):
    pytest.importorskip("numba")
    expected = gnc_legs[-1]
    got = peers.numba_entry_rk4()(entry.states, entry.params, entry.consts, DT_S, LEGS * STEPS)
    moved = np.linalg.norm(expected[:, :3] - entry.states[:, :3], axis=1)
    assert np.all(moved > 1e6)  # the arcs went somewhere (thousands of km)
    for block in (slice(0, 3), slice(3, 6)):
        scale = np.linalg.norm(expected[:, block], axis=1)
        error = np.linalg.norm(got[:, block] - expected[:, block], axis=1)
        assert np.all(error <= 1e-9 * scale), error / scale


def test_component_wise_rk4_equals_gnc_jax_rk4(peers, entry, gnc_legs):
    """The benchmark's structure-of-arrays variant integrates the same equations."""
    items = (jnp.asarray(entry.states), jnp.asarray(entry.params))
    arc = jax.vmap(
        lambda item: peers._entry_arc_components(
            jnp.asarray(entry.consts), item, DT_S, STEPS, peers.RK4
        )
    )
    got = np.asarray(jax.jit(arc)(items))
    expected = gnc_legs[0]
    for block in (slice(0, 3), slice(3, 6)):
        scale = np.linalg.norm(expected[:, block], axis=1)
        error = np.linalg.norm(got[:, block] - expected[:, block], axis=1)
        assert np.all(error <= 1e-11 * scale), error / scale


@pytest.mark.parametrize("leg", [0, 1, 3], ids=["entry", "100s", "300s"])
def test_heyoka_entry_field_equals_gnc_jax(peers, entry, gnc_legs, leg):
    import heyoka as hy

    states = entry.states if leg == 0 else gnc_legs[leg - 1]
    variables, rhs = peers.heyoka_entry_rhs(entry.consts)
    got = hy.cfunc(rhs, vars=variables)(
        np.ascontiguousarray(states.T), pars=np.ascontiguousarray(entry.params.T)
    ).T
    expected = _gnc_field(entry, states)
    np.testing.assert_array_equal(got[:, :3], expected[:, :3])
    error = np.linalg.norm(got[:, 3:] - expected[:, 3:], axis=1)
    assert np.all(error <= 1e-12 * np.linalg.norm(expected[:, 3:], axis=1)), error
    # the plain-Python transcription (scipy's field and the reference) agrees too
    plain = np.empty_like(states)
    for i, (s, p) in enumerate(zip(states, entry.params)):
        peers.entry_rhs(s, p, entry.consts, plain[i])
    error = np.linalg.norm(plain[:, 3:] - expected[:, 3:], axis=1)
    assert np.all(error <= 1e-12 * np.linalg.norm(expected[:, 3:], axis=1)), error


def test_entry_states_cover_the_dip(entry, gnc_legs):
    """The field checks above include states deep in the atmosphere (aerodynamic
    acceleration above 1 g), where the lift and drag terms dominate."""
    from gnc_jax.dynamics.entry import gravity_acceleration

    states = gnc_legs[0]
    gravity = np.asarray(jax.vmap(lambda r: gravity_acceleration(r, entry.earth))(states[:, :3]))
    aero = _gnc_field(entry, states)[:, 3:] - gravity
    assert np.max(np.linalg.norm(aero, axis=1)) > 9.8


def _cruise_states():
    """Heliocentric states at epochs of 2007-2008: on the cruise, and near Earth and Mars."""
    rng = np.random.default_rng(1)
    epochs = 2.42e8 + 2.0e7 * rng.random(6)
    states = []
    for k, t in enumerate(epochs):
        body = (2, 3, None, None, 2, 3)[k]
        if body is None:
            r = 1.5e11 * rng.standard_normal(3) / np.sqrt(3)
        else:
            r = np.asarray(ephemeris.planet_state(body, t)[0]) + 2e7 * rng.standard_normal(3)
        states.append(np.concatenate([r, 3e4 * rng.standard_normal(3) / np.sqrt(3)]))
    return epochs, np.array(states)


@pytest.mark.parametrize("sun", [True, False], ids=["full", "planets-only"])
def test_heyoka_cruise_field_equals_gnc_jax(peers, sun):
    import heyoka as hy

    model = HeliocentricModel(srp_m2_per_kg=jnp.asarray(0.0137 if sun else 0.0))
    if not sun:  # the planet terms alone, where they dominate
        model = HeliocentricModel(gm_sun=jnp.asarray(0.0))
    epochs, states = _cruise_states()
    variables, rhs = peers.heyoka_cruise_rhs(model)
    got = hy.cfunc(rhs, vars=variables)(np.ascontiguousarray(states.T), time=epochs).T
    expected = np.asarray(jax.vmap(lambda t, y: vector_field(t, y, model))(epochs, states))
    error = np.linalg.norm(got[:, 3:] - expected[:, 3:], axis=1)
    # plan94 in both: Kepler's equation solved to rounding on both sides
    assert np.all(error <= 1e-10 * np.linalg.norm(expected[:, 3:], axis=1)), error


def test_erfa_cruise_field_equals_gnc_jax(peers):
    pytest.importorskip("erfa")
    model = HeliocentricModel(srp_m2_per_kg=jnp.asarray(0.0137))
    epochs, states = _cruise_states()
    f = peers.erfa_cruise_rhs(model)
    got = np.array([f(t, y) for t, y in zip(epochs, states)])
    expected = np.asarray(jax.vmap(lambda t, y: vector_field(t, y, model))(epochs, states))
    # ERFA's plan94 and gnc_jax's agree to ~1e-13 au (1.5 cm): near a planet (2e4 km)
    # that moves its pull by ~1e-9 of itself
    error = np.linalg.norm(got[:, 3:] - expected[:, 3:], axis=1)
    assert np.all(error <= 1e-8 * np.linalg.norm(expected[:, 3:], axis=1)), error
