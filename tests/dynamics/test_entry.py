import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnc_jax.dynamics.atmosphere import Atmosphere
from gnc_jax.dynamics.entry import (
    G0,
    BankActuator,
    EarthModel,
    EntryArgs,
    EntryConditions,
    EntryState,
    EntryVehicle,
    aerodynamic_acceleration,
    altitude,
    earth_relative_velocity,
    entry_conditions_from_state,
    entry_state_from_conditions,
    entry_vector_field,
    flight_path_angle,
    geocentric_latitude_longitude,
    lift_direction,
    sensed_load_g,
    sutton_graves_heat_rate,
)
from gnc_jax.integrate import integrate_fixed

DEG = math.pi / 180.0


def _conditions(alt_m, speed_mps, gamma_deg, azimuth_deg, lon_deg, lat_deg) -> EntryConditions:
    angles = (gamma_deg, azimuth_deg, lon_deg, lat_deg)
    return EntryConditions(
        *(jnp.asarray(x) for x in (alt_m, speed_mps)), *(jnp.asarray(a * DEG) for a in angles)
    )


# Seed 003 Table 1: 120 km, 11 km/s, gamma -5.9 deg, azimuth 34.3 deg, lon 63.54, lat -3.34 deg.
SEED_ENTRY = _conditions(120e3, 11e3, -5.9, 34.3, 63.54, -3.34)


def _flat(state: EntryState) -> np.ndarray:
    return np.concatenate([np.asarray(state.r), np.asarray(state.v)])


def _flat_field(args):
    """The package vector field as f(t, y_flat) -> ydot_flat, for scipy."""

    @jax.jit
    def f(t, y):
        d = entry_vector_field(t, EntryState(y[:3], y[3:]), args)
        return jnp.concatenate([d.r, d.v])

    return lambda t, y: np.asarray(f(t, y))


# 60 deg: first entry, pull-up and skip out. 150 deg: lift-down plunge through a ~36 g peak to
# 25 km (stopped before the flight turns vertical, where the bank angle is undefined).
@pytest.mark.parametrize("bank_deg, duration_s", [(60.0, 600.0), (150.0, 120.0)])
def test_rk4_matches_dop853_over_atmospheric_arc(bank_deg, duration_s):
    solve_ivp = pytest.importorskip("scipy.integrate").solve_ivp
    earth = EarthModel()
    args = EntryArgs(EntryVehicle(), earth, Atmosphere("us76"), jnp.asarray(bank_deg * DEG))
    y0 = entry_state_from_conditions(SEED_ENTRY, earth)
    dt = 0.1
    n_steps = round(duration_s / dt)
    ours = jax.jit(integrate_fixed, static_argnums=(0, 4))(
        entry_vector_field, 0.0, y0, dt, n_steps, args
    )
    ref = solve_ivp(
        _flat_field(args), (0.0, duration_s), _flat(y0), method="DOP853", rtol=1e-12, atol=1e-6
    )
    assert ref.success
    # The arc is atmospheric: it reaches several g (so lift, drag and density all matter).
    peak_load = max(
        float(
            sensed_load_g(
                jnp.asarray(y[:3]), jnp.asarray(y[3:]), args.vehicle, earth, args.atmosphere
            )
        )
        for y in ref.y.T
    )
    assert peak_load > 2.0
    np.testing.assert_allclose(np.asarray(ours.r), ref.y[:3, -1], rtol=0, atol=1.0)
    np.testing.assert_allclose(np.asarray(ours.v), ref.y[3:, -1], rtol=0, atol=1e-3)


def _spherical_earth_relative(t, state: EntryState, earth: EarthModel):
    """(r, longitude, latitude, V, gamma, psi) with Earth-relative velocity, psi from north."""
    c = entry_conditions_from_state(state, earth, t)
    return jnp.stack(
        [
            jnp.linalg.norm(state.r),
            c.longitude,
            c.latitude,
            c.speed_mps,
            c.flight_path_angle,
            c.azimuth,
        ]
    )


def _vinh_rotating_spherical(x, bank, lift, drag, mu, omega):
    """Entry equations over a rotating spherical Earth in (r, theta, phi, V, gamma, psi), psi
    clockwise from north (Vinh 1980; the dimensional form of Lu 2014, JGCD 37(3), eqs. 1-6)."""
    r, _, phi, v, gamma, psi = x
    g = mu / r**2
    sg, cg, sp, cp, ss, cs = (
        np.sin(gamma),
        np.cos(gamma),
        np.sin(phi),
        np.cos(phi),
        np.sin(psi),
        np.cos(psi),
    )
    return np.array(
        [
            v * sg,
            v * cg * ss / (r * cp),
            v * cg * cs / r,
            -drag - g * sg + omega**2 * r * cp * (sg * cp - cg * sp * cs),
            (
                lift * np.cos(bank)
                + (v**2 - g * r) * cg / r
                + 2 * omega * v * cp * ss
                + omega**2 * r * cp * (cg * cp + sg * sp * cs)
            )
            / v,
            (
                lift * np.sin(bank) / cg
                + v**2 * cg * ss * np.tan(phi) / r
                - 2 * omega * v * (np.tan(gamma) * cp * cs - sp)
                + omega**2 * r * sp * cp * ss / cg
            )
            / v,
        ]
    )


@pytest.mark.parametrize("bank_deg", [-120.0, -30.0, 0.0, 45.0, 100.0])
def test_cartesian_field_equals_rotating_spherical_equations(bank_deg):
    # J2 = 0 (the classical equations use point-mass gravity); rotation on, exponential air.
    earth = EarthModel(j2=0.0)
    vehicle = EntryVehicle(lift_scale=1.1, drag_scale=0.9)
    atmosphere = Atmosphere("exponential")
    bank = bank_deg * DEG
    args = EntryArgs(vehicle, earth, atmosphere, jnp.asarray(bank))
    rng = np.random.default_rng(3)
    for _ in range(4):
        conditions = _conditions(
            rng.uniform(40e3, 90e3),
            rng.uniform(6e3, 11e3),
            rng.uniform(-8, 3),
            rng.uniform(-180, 180),
            rng.uniform(-150, 150),
            rng.uniform(-60, 60),
        )
        t = rng.uniform(0.0, 3000.0)
        state = entry_state_from_conditions(conditions, earth, t)
        # Chain rule: d/dt of the spherical coordinates along the Cartesian field.
        _, rates = jax.jvp(
            lambda tt, y: _spherical_earth_relative(tt, y, earth),
            (jnp.asarray(t), state),
            (jnp.asarray(1.0), entry_vector_field(t, state, args)),
        )
        x = np.asarray(_spherical_earth_relative(t, state, earth))
        rho = float(atmosphere.density(conditions.altitude_m))
        q_s_over_m = 0.5 * rho * x[3] ** 2 * 22.0 / 9000.0
        expected = _vinh_rotating_spherical(
            x, bank, q_s_over_m * 0.39 * 1.1, q_s_over_m * 1.3 * 0.9, 3.986004418e14, 7.2921159e-5
        )
        scale = np.array([x[3], x[3] / x[0], x[3] / x[0], 10.0, x[3] / x[0], x[3] / x[0]])
        np.testing.assert_allclose(np.asarray(rates) / scale, expected / scale, rtol=0, atol=1e-11)


def _orbit_args(j2: float) -> EntryArgs:
    earth = EarthModel(j2=j2, rotation_rate=0.0)
    vehicle = EntryVehicle(lift_coefficient=0.0, drag_coefficient=0.0)
    return EntryArgs(vehicle, earth, Atmosphere("us76"), jnp.asarray(0.3))


def _elliptic_orbit(earth: EarthModel) -> EntryState:
    # 300 km x ~2400 km, inclined 51.6 deg: starts at perigee over 20 deg latitude.
    return entry_state_from_conditions(
        _conditions(300e3, 8.3e3, 0.0, 40.0, 10.0, 20.0),
        earth,
    )


def test_drag_free_point_mass_conserves_energy_and_angular_momentum():
    args = _orbit_args(j2=0.0)
    y0 = _elliptic_orbit(args.earth)
    y1 = jax.jit(integrate_fixed, static_argnums=(0, 4))(
        entry_vector_field, 0.0, y0, 0.5, 16_000, args
    )
    mu = 3.986004418e14

    def energy(y):
        return 0.5 * jnp.dot(y.v, y.v) - mu / jnp.linalg.norm(y.r)

    assert float(jnp.linalg.norm(y1.r - y0.r)) > 1e6  # it moved around the orbit
    assert float(abs(energy(y1) / energy(y0) - 1.0)) < 1e-10
    h0, h1 = jnp.cross(y0.r, y0.v), jnp.cross(y1.r, y1.v)
    assert float(jnp.linalg.norm(h1 - h0) / jnp.linalg.norm(h0)) < 1e-10


def test_j2_conserves_polar_angular_momentum_and_energy():
    args = _orbit_args(j2=1.08262668e-3)
    earth = args.earth
    y0 = _elliptic_orbit(earth)
    y1 = jax.jit(integrate_fixed, static_argnums=(0, 4))(
        entry_vector_field, 0.0, y0, 0.5, 16_000, args
    )

    def energy(y):  # J2 potential: U = -mu/r [1 - J2 (R/r)^2 (3 sin^2 phi - 1) / 2]
        r = jnp.linalg.norm(y.r)
        s2 = (y.r[2] / r) ** 2
        u = (
            -earth.mu
            / r
            * (1.0 - earth.j2 * (earth.equatorial_radius_m / r) ** 2 * (3.0 * s2 - 1.0) / 2.0)
        )
        return 0.5 * jnp.dot(y.v, y.v) + u

    h0, h1 = jnp.cross(y0.r, y0.v), jnp.cross(y1.r, y1.v)
    assert float(abs(h1[2] / h0[2] - 1.0)) < 1e-10
    assert float(abs(energy(y1) / energy(y0) - 1.0)) < 1e-10
    # ...while the orbit plane precesses: the in-plane components of h do change.
    assert float(jnp.linalg.norm(h1[:2] - h0[:2]) / jnp.linalg.norm(h0)) > 1e-5


@pytest.mark.parametrize("t", [0.0, 1234.5])
def test_entry_conditions_round_trip(t):
    earth = EarthModel()
    rng = np.random.default_rng(7)
    for _ in range(20):
        c = _conditions(
            rng.uniform(0.0, 200e3),
            rng.uniform(100.0, 12e3),
            rng.uniform(-80, 80),
            rng.uniform(-179, 179),
            rng.uniform(-179, 179),
            rng.uniform(-85, 85),
        )
        back = entry_conditions_from_state(entry_state_from_conditions(c, earth, t), earth, t)
        np.testing.assert_allclose(back.altitude_m, c.altitude_m, atol=1e-6)
        np.testing.assert_allclose(back.speed_mps, c.speed_mps, rtol=1e-12)
        for name in ("flight_path_angle", "azimuth", "longitude", "latitude"):
            np.testing.assert_allclose(getattr(back, name), getattr(c, name), atol=1e-11)


def test_entry_state_closed_form_at_equator_heading_east():
    earth = EarthModel()
    c = _conditions(100e3, 7e3, 0.0, 90.0, 0.0, 0.0)
    state = entry_state_from_conditions(c, earth)
    radius = 6378137.0 + 100e3
    np.testing.assert_allclose(state.r, [radius, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(state.v, [0.0, 7e3 + 7.2921159e-5 * radius, 0.0], atol=1e-9)
    # A quarter of a sidereal-day rotation later the same inertial point is 90 deg further west.
    lat, lon = geocentric_latitude_longitude(state.r, 0.5 * math.pi / 7.2921159e-5, earth)
    np.testing.assert_allclose([lat, lon], [0.0, -0.5 * math.pi], atol=1e-12)
    assert float(altitude(state.r, earth)) == pytest.approx(100e3)
    v_rel = earth_relative_velocity(state.r, state.v, earth)
    assert float(flight_path_angle(state.r, v_rel)) == pytest.approx(0.0, abs=1e-15)


def test_bank_sign_convention_lift_to_the_right():
    # At the equator flying north (ECI +z), "up" is +x; the right-hand side is east (+y).
    r = jnp.array([6.5e6, 0.0, 0.0])
    v_rel = jnp.array([0.0, 0.0, 7e3])
    np.testing.assert_allclose(lift_direction(r, v_rel, 0.0), [1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(lift_direction(r, v_rel, 0.5 * math.pi), [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(lift_direction(r, v_rel, math.pi), [-1.0, 0.0, 0.0], atol=1e-15)


def test_sensed_load_and_heat_rate():
    earth, vehicle, atmosphere = EarthModel(), EntryVehicle(), Atmosphere("us76")
    state = entry_state_from_conditions(_conditions(60e3, 9e3, -2.0, 10.0, 17.0, 11.0), earth)
    aero = aerodynamic_acceleration(state.r, state.v, 0.7, vehicle, earth, atmosphere)
    load = sensed_load_g(state.r, state.v, vehicle, earth, atmosphere)
    np.testing.assert_allclose(load, jnp.linalg.norm(aero) / G0, rtol=1e-13)
    rho = 3.0968e-4  # US76 at 60 km, kg/m^3
    np.testing.assert_allclose(
        load, 0.5 * rho * 9e3**2 * 22.0 * math.hypot(0.39, 1.3) / (9000.0 * 9.80665), rtol=2e-3
    )
    # Sutton-Graves closed form: 1.7415e-4 sqrt(1e-4 / 1) (1e4)^3 = 1.7415e6 W/m^2.
    np.testing.assert_allclose(sutton_graves_heat_rate(1e-4, 1e4, 1.0), 1.7415e6, rtol=1e-14)


def test_vector_field_vmaps_over_vehicle_dispersions():
    earth, atmosphere = EarthModel(), Atmosphere("us76")
    state = entry_state_from_conditions(SEED_ENTRY._replace(altitude_m=jnp.asarray(70e3)), earth)
    drag_scales = jnp.array([0.8, 1.0, 1.2])
    banks = jnp.array([-0.5, 0.1, 1.2])

    def field(drag_scale, bank):
        args = EntryArgs(EntryVehicle(drag_scale=drag_scale), earth, atmosphere, bank)
        return entry_vector_field(0.0, state, args).v

    batched = jax.vmap(field)(drag_scales, banks)
    looped = jnp.stack([field(d, b) for d, b in zip(drag_scales, banks)])
    np.testing.assert_allclose(batched, looped, rtol=1e-14)
    grad = jax.grad(lambda d: field(d, 0.3)[0])(1.0)
    assert bool(jnp.isfinite(grad)) and float(grad) != 0.0


def test_integration_does_not_retrace_for_new_parameters():
    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def fly(y0, args):
        return integrate_fixed(entry_vector_field, 0.0, y0, 0.5, 20, args)

    earth = EarthModel()
    y0 = entry_state_from_conditions(SEED_ENTRY, earth)
    for drag_scale, bank in [(1.0, 0.2), (1.2, -0.7), (0.8, 1.0)]:
        vehicle = EntryVehicle(drag_scale=drag_scale)
        fly(y0, EntryArgs(vehicle, earth, Atmosphere("us76", density_scale=1.1), jnp.asarray(bank)))


def _time_optimal_bank(t, angle, max_rate, max_accel):
    """Continuous-time rest-to-rest profile with rate and acceleration limits (bang-coast-bang)."""
    t_ramp = max_rate / max_accel
    if angle < max_rate * t_ramp:  # triangular profile
        t_ramp = math.sqrt(angle / max_accel)
        max_rate = max_accel * t_ramp
    t_coast = angle / max_rate - t_ramp
    t_end = 2 * t_ramp + t_coast
    if t <= t_ramp:
        return 0.5 * max_accel * t**2
    if t <= t_ramp + t_coast:
        return 0.5 * max_rate * t_ramp + max_rate * (t - t_ramp)
    if t <= t_end:
        return angle - 0.5 * max_accel * (t_end - t) ** 2
    return angle


@pytest.mark.parametrize("command_deg", [60.0, -15.0, 180.0])
def test_bank_actuator_respects_limits_and_tracks_time_optimal_profile(command_deg):
    actuator = BankActuator()
    dt = 0.05
    command = command_deg * DEG

    def step(state, _):
        new = actuator.step(state, command, dt)
        return new, new

    _, history = jax.lax.scan(step, actuator.init(0.0), None, length=int(20.0 / dt))
    bank, rate = np.asarray(history.bank), np.asarray(history.bank_rate)
    max_rate, max_accel = 20.0 * DEG, 10.0 * DEG
    assert np.max(np.abs(rate)) <= max_rate * (1 + 1e-12)
    accel = np.diff(np.concatenate([[0.0], rate])) / dt
    assert np.max(np.abs(accel)) <= max_accel * (1 + 1e-9)
    # Within one step of travel of the continuous time-optimal manoeuvre (the discrete update
    # leads it by up to max_rate dt / 2), then settled on the command.
    t = dt * np.arange(1, bank.size + 1)
    ideal = np.sign(command) * np.array(
        [_time_optimal_bank(tk, abs(command), max_rate, max_accel) for tk in t]
    )
    wrapped = lambda a: np.remainder(a + np.pi, 2.0 * np.pi) - np.pi  # noqa: E731 (180 = -180)
    assert np.max(np.abs(wrapped(bank - ideal))) < max_rate * dt
    np.testing.assert_allclose(wrapped(bank[-20:] - command), 0.0, atol=1e-9)
    np.testing.assert_allclose(rate[-20:], 0.0, atol=1e-9)


def _roll(actuator, bank0, commands, dt=0.05, seconds=30.0):
    """Bank history of ``actuator`` from rest at ``bank0`` (deg); ``commands``: (from time s,
    command deg) pairs, the last one given holds."""
    n = int(seconds / dt)
    t = dt * np.arange(n)
    cmd = np.zeros(n)
    for t0, c in commands:
        cmd[t >= t0] = c * DEG

    def step(state, c):
        new = actuator.step(state, c, dt)
        return new, new.bank

    _, bank = jax.lax.scan(step, actuator.init(bank0 * DEG), jnp.asarray(cmd))
    return np.degrees(np.asarray(bank))


def test_bank_reversal_ways_round():
    """Default: a reversal between two lift-down banks rolls through lift-down (the angle flown
    stays in (-180, 180]), one between lift-up banks through lift-up, and a roll under way keeps
    its way round when the command changes; ``shortest=False`` rolls every reversal through
    lift-up."""
    default, straight = BankActuator(), BankActuator(way="through_lift_up")
    down = _roll(default, 120.0, [(0.0, -120.0)])
    slack = 1.0  # deg: the discrete braking overshoots by up to max_rate dt
    assert np.all(np.abs(down) >= 120.0 - slack) and np.all(np.abs(down) <= 180.0)
    np.testing.assert_allclose(down[-1], -120.0, atol=1e-9)
    up = _roll(default, 60.0, [(0.0, -60.0)])
    assert np.all(np.abs(up) <= 60.0 + slack)
    np.testing.assert_allclose(up[-1], -60.0, atol=1e-9)
    # under way through lift-down when the command becomes a lift-up bank: no turn back
    changed = _roll(default, 120.0, [(0.0, -120.0), (4.0, -80.0)])
    assert np.all(np.abs(changed) >= 80.0 - slack)
    np.testing.assert_allclose(changed[-1], -80.0, atol=1e-9)
    old = _roll(straight, 120.0, [(0.0, -120.0)])
    assert np.min(np.abs(old)) < 1.0
    np.testing.assert_allclose(old[-1], -120.0, atol=1e-9)


def test_a_reversal_to_lift_down_never_rolls_through_lift_up():
    """``way = "shortest"`` (the default): from a lift-up hold (+60 deg) to a lift-down
    command (-178 deg) the capsule rolls through lift-down (the old ``"lift_down_pairs"``
    rolled 238 deg through lift-up); reversals commanded in quick succession between lift-down
    banks keep the bank beyond 90 deg, where the old rule, a roll under way keeping its way,
    turned it through lift-up."""
    new, old = BankActuator(), BankActuator(way="lift_down_pairs")
    down = _roll(new, 60.0, [(0.0, -178.0)])
    assert np.min(np.abs(down)) >= 60.0 - 1e-9
    np.testing.assert_allclose(down[-1], -178.0, atol=1e-9)
    assert np.min(np.abs(_roll(old, 60.0, [(0.0, -178.0)]))) < 1.0
    # -118 -> +118 through lift-down; 6 s later, still rolling, the sign flips back
    chatter = [(0.0, 118.0), (6.0, -124.0)]
    back = _roll(new, -118.0, chatter)
    assert np.min(np.abs(back)) > 115.0
    np.testing.assert_allclose(back[-1], -124.0, atol=1e-9)
    assert np.min(np.abs(_roll(old, -118.0, chatter))) < 1.0  # a whole turn through lift-up
