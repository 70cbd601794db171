"""Point-mass (3-DOF) atmospheric entry over a rotating Earth with J2 (seed 003 §1, SPEC §8).

Seed 003 writes the equations of motion in its rotating "return frame" (eqs. 1-5). The same
physics is written here in Earth-centred inertial (ECI) Cartesian coordinates, which keeps the
Coriolis and centripetal terms out of the equations and trigonometry out of the inner loop:

    dr/dt = v,    dv/dt = g_J2(r) + a_aero(r, v - omega_E x r, sigma).

Frames and conventions
- ECI: z along the Earth's spin axis; the Earth-fixed frame coincides with ECI at t = 0 and turns
  about z at ``EarthModel.rotation_rate``. Longitude is east-positive from the Earth-fixed x axis.
- Earth model: spherical for geometry (seed 003 §1, "spherical Earth"): altitude is |r| - R_E and
  latitude is geocentric, as in seed 003 eq. 3. Gravity adds the J2 zonal term.
- The atmosphere rotates with the Earth: the air-relative velocity is v_rel = v - omega_E x r.
- Flight-path angle gamma: angle of a velocity above the local horizontal (negative descending).
  Azimuth (heading) psi: angle of its horizontal projection clockwise from north (90 deg = east).
- Bank angle sigma: rotation of the lift vector about v_rel, measured from "lift up" (the
  component of r_hat perpendicular to v_rel). sigma > 0 tilts lift to the RIGHT of the velocity,
  i.e. towards v_rel x r_hat (east for a vehicle flying north), and turns the heading clockwise
  (d psi/dt has the sign of sin sigma). Note v_rel x r_hat, not -(v_rel x r_hat): the latter is
  the left side. The bank angle is undefined for vertical flight (v_rel parallel to r), where
  "up" has no perpendicular component; entry trajectories stop (chute deploy) well before that.
"""

import math
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from .._types import Array, Float, Scalar, Vector3
from .atmosphere import Atmosphere

G0 = 9.80665  # m/s^2, standard gravity: the unit of the sensed load N_g
SUTTON_GRAVES_K_EARTH = 1.7415e-4  # kg^0.5/m: Sutton-Graves constant for air, SI units


class EarthModel(eqx.Module):
    """Gravity and rotation of the Earth (seed 003 eq. 3), SI units.

    Attributes:
        mu: gravitational parameter, m^3/s^2 (EGM96/WGS84 value).
        equatorial_radius_m: a_e of eq. 3 and the radius of the spherical Earth, m (WGS84).
        j2: second zonal harmonic (EGM96, unnormalised).
        rotation_rate: omega_E, rad/s (IERS).
    Zero ``j2`` gives point-mass gravity; zero ``rotation_rate`` a non-rotating Earth.
    """

    mu: Scalar = eqx.field(default=3.986004418e14, converter=jnp.asarray)
    equatorial_radius_m: Scalar = eqx.field(default=6378137.0, converter=jnp.asarray)
    j2: Scalar = eqx.field(default=1.08262668e-3, converter=jnp.asarray)
    rotation_rate: Scalar = eqx.field(default=7.2921159e-5, converter=jnp.asarray)

    def angular_velocity(self) -> Vector3:
        """omega_E as an ECI vector, rad/s."""
        return jnp.array([0.0, 0.0, 1.0]) * self.rotation_rate


class EntryVehicle(eqx.Module):
    """Capsule parameters (what a dispersion draws), SI units.

    Defaults: mass and reference area from seed 003 §4.1 (9000 kg, 22 m^2). The seed gives no
    aerodynamics; SPEC §8 fixes L/D = 0.3 for an Apollo/Orion-class capsule at trim, here as
    C_D = 1.3 and C_L = 0.39 (Apollo trims at C_D ~ 1.2-1.3, L/D ~ 0.3; Orion similar). The
    nose radius is 1.2 times the diameter of a disc of area S (the spherical-segment heat
    shields of Apollo and Orion both have R_n ~ 1.2 D): 6.35 m.

    Attributes:
        mass_kg: mass, kg.
        reference_area_m2: aerodynamic reference area S, m^2.
        lift_coefficient: nominal C_L at trim.
        drag_coefficient: nominal C_D at trim.
        lift_scale, drag_scale: dispersion multipliers on C_L and C_D (seed 003 Table 2).
        nose_radius_m: stagnation-point nose radius for the Sutton-Graves heat rate, m.
    """

    mass_kg: Scalar = eqx.field(default=9000.0, converter=jnp.asarray)
    reference_area_m2: Scalar = eqx.field(default=22.0, converter=jnp.asarray)
    lift_coefficient: Scalar = eqx.field(default=0.39, converter=jnp.asarray)
    drag_coefficient: Scalar = eqx.field(default=1.3, converter=jnp.asarray)
    lift_scale: Scalar = eqx.field(default=1.0, converter=jnp.asarray)
    drag_scale: Scalar = eqx.field(default=1.0, converter=jnp.asarray)
    nose_radius_m: Scalar = eqx.field(default=6.35, converter=jnp.asarray)

    @property
    def c_l(self) -> Scalar:
        """Dispersed lift coefficient."""
        return self.lift_coefficient * self.lift_scale

    @property
    def c_d(self) -> Scalar:
        """Dispersed drag coefficient."""
        return self.drag_coefficient * self.drag_scale


class EntryState(NamedTuple):
    """Inertial Cartesian state: ECI position ``r`` (m) and velocity ``v`` (m/s)."""

    r: Vector3
    v: Vector3


class EntryArgs(NamedTuple):
    """``args`` of `entry_vector_field`: the bank angle (rad) is held over the step."""

    vehicle: EntryVehicle
    earth: EarthModel
    atmosphere: Atmosphere
    bank: Scalar


class EntryConditions(NamedTuple):
    """Entry interface in Earth-relative terms (seed 003 Table 1), SI units and radians.

    ``speed_mps``, ``flight_path_angle`` and ``azimuth`` describe the Earth-relative velocity;
    ``latitude`` is geocentric, ``longitude`` east-positive; ``altitude_m`` above the sphere.
    """

    altitude_m: Scalar
    speed_mps: Scalar
    flight_path_angle: Scalar
    azimuth: Scalar
    longitude: Scalar
    latitude: Scalar


def _unit(x: Float[Array, "3"]) -> Float[Array, "3"]:
    # Guarded so that a zero vector (and its gradient) gives zeros instead of NaN.
    n2 = jnp.dot(x, x)
    safe = jnp.where(n2 > 0.0, n2, 1.0)
    return jnp.where(n2 > 0.0, x / jnp.sqrt(safe), 0.0)


def altitude(r: Vector3, earth: EarthModel) -> Scalar:
    """Altitude above the spherical Earth, |r| - R_E, m."""
    return jnp.linalg.norm(r) - earth.equatorial_radius_m


def earth_relative_velocity(r: Vector3, v: Vector3, earth: EarthModel) -> Vector3:
    """Velocity relative to the rotating Earth and its air, v - omega_E x r, ECI axes, m/s."""
    return v - jnp.cross(earth.angular_velocity(), r)


def flight_path_angle(r: Vector3, v: Vector3) -> Scalar:
    """Angle of ``v`` above the local horizontal, asin(r_hat . v_hat), rad.

    Pass `earth_relative_velocity` for the Earth-relative angle, ``v`` for the inertial one.
    """
    return jnp.arcsin(jnp.clip(jnp.dot(_unit(r), _unit(v)), -1.0, 1.0))


def geocentric_latitude_longitude(
    r: Vector3, t: Scalar, earth: EarthModel
) -> tuple[Scalar, Scalar]:
    """Geocentric latitude and east longitude (rad) of ECI position ``r`` at time ``t`` (s).

    Longitude = atan2(y, x) - omega_E t, wrapped to (-pi, pi]. The model Earth is a sphere, so
    geocentric latitude is the one that enters gravity (seed 003 eq. 3) and the entry point.
    """
    latitude = jnp.arcsin(jnp.clip(r[2] / jnp.linalg.norm(r), -1.0, 1.0))
    longitude = jnp.arctan2(r[1], r[0]) - earth.rotation_rate * t
    longitude = jnp.arctan2(jnp.sin(longitude), jnp.cos(longitude))
    return latitude, longitude


def _east_north_up(latitude: Scalar, longitude: Scalar) -> tuple[Vector3, Vector3, Vector3]:
    """Local east, north, up unit vectors in the Earth-fixed frame."""
    sl, cl = jnp.sin(latitude), jnp.cos(latitude)
    so, co = jnp.sin(longitude), jnp.cos(longitude)
    east = jnp.array([-so, co, 0.0])
    north = jnp.array([-sl * co, -sl * so, cl])
    up = jnp.array([cl * co, cl * so, sl])
    return east, north, up


def _rotation_about_z(angle: Scalar) -> Float[Array, "3 3"]:
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def entry_state_from_conditions(
    conditions: EntryConditions, earth: EarthModel, t: Scalar = 0.0
) -> EntryState:
    """ECI state at time ``t`` (s) from Earth-relative entry conditions.

    r = (R_E + h) u;  v_rel = V (cos gamma sin psi e + cos gamma cos psi n + sin gamma u)
    in the local east-north-up frame, rotated by omega_E t into ECI; v = v_rel + omega_E x r.
    """
    c = conditions
    east, north, up = _east_north_up(c.latitude, c.longitude)
    v_rel_fixed = c.speed_mps * (
        jnp.cos(c.flight_path_angle) * (jnp.sin(c.azimuth) * east + jnp.cos(c.azimuth) * north)
        + jnp.sin(c.flight_path_angle) * up
    )
    to_eci = _rotation_about_z(earth.rotation_rate * t)
    r = to_eci @ ((earth.equatorial_radius_m + c.altitude_m) * up)
    v = to_eci @ v_rel_fixed + jnp.cross(earth.angular_velocity(), r)
    return EntryState(r, v)


def entry_conditions_from_state(
    state: EntryState, earth: EarthModel, t: Scalar = 0.0
) -> EntryConditions:
    """Earth-relative entry conditions of an ECI state at time ``t`` (s); inverse of
    `entry_state_from_conditions`."""
    r, v = state
    latitude, longitude = geocentric_latitude_longitude(r, t, earth)
    v_rel = earth_relative_velocity(r, v, earth)
    # Local frame in ECI axes: the Earth-fixed one at the inertial longitude of r.
    east, north, up = _east_north_up(latitude, jnp.arctan2(r[1], r[0]))
    return EntryConditions(
        altitude_m=altitude(r, earth),
        speed_mps=jnp.linalg.norm(v_rel),
        flight_path_angle=flight_path_angle(r, v_rel),
        azimuth=jnp.arctan2(jnp.dot(v_rel, east), jnp.dot(v_rel, north)),
        longitude=longitude,
        latitude=latitude,
    )


def gravity_acceleration(r: Vector3, earth: EarthModel) -> Vector3:
    """Gravity with J2, seed 003 eq. 3: g = g_r r_hat + g_omega omega_hat, m/s^2.

    g_r = -mu/r^2 [1 + 3/2 J2 (a_e/r)^2 (1 - 5 sin^2 phi)],
    g_omega = -3 mu/r^2 J2 (a_e/r)^2 sin phi, with phi the geocentric latitude and omega_hat
    the spin axis (ECI z).
    """
    r_norm = jnp.linalg.norm(r)
    sin_lat = r[2] / r_norm
    mu_r2 = earth.mu / r_norm**2
    j2_term = earth.j2 * (earth.equatorial_radius_m / r_norm) ** 2
    g_r = -mu_r2 * (1.0 + 1.5 * j2_term * (1.0 - 5.0 * sin_lat**2))
    g_omega = -3.0 * mu_r2 * j2_term * sin_lat
    return g_r * r / r_norm + g_omega * jnp.array([0.0, 0.0, 1.0])


def dynamic_pressure(r: Vector3, v: Vector3, earth: EarthModel, atmosphere: Atmosphere) -> Scalar:
    """q = 1/2 rho |v_rel|^2, Pa."""
    v_rel = earth_relative_velocity(r, v, earth)
    return 0.5 * atmosphere.density(altitude(r, earth)) * jnp.dot(v_rel, v_rel)


def lift_direction(r: Vector3, v_rel: Vector3, bank: Scalar) -> Vector3:
    """Unit lift vector: cos(sigma) up_perp + sin(sigma) (v_hat x up_perp).

    up_perp is the component of r_hat perpendicular to v_rel, normalised; v_hat x up_perp is the
    right-hand side of the velocity (see the module docstring for the sign convention).
    """
    v_hat = _unit(v_rel)
    r_hat = _unit(r)
    up = _unit(r_hat - jnp.dot(r_hat, v_hat) * v_hat)
    right = jnp.cross(v_hat, up)
    return jnp.cos(bank) * up + jnp.sin(bank) * right


def aerodynamic_acceleration(
    r: Vector3,
    v: Vector3,
    bank: Scalar,
    vehicle: EntryVehicle,
    earth: EarthModel,
    atmosphere: Atmosphere,
) -> Vector3:
    """Lift plus drag per unit mass in ECI axes, m/s^2.

    D = q S C_D / m along -v_rel;  L = q S C_L / m along `lift_direction` (bank ``sigma``).
    """
    v_rel = earth_relative_velocity(r, v, earth)
    q_s_over_m = (
        0.5
        * atmosphere.density(altitude(r, earth))
        * jnp.dot(v_rel, v_rel)
        * vehicle.reference_area_m2
        / vehicle.mass_kg
    )
    drag = -q_s_over_m * vehicle.c_d * _unit(v_rel)
    lift = q_s_over_m * vehicle.c_l * lift_direction(r, v_rel, bank)
    return drag + lift


def entry_vector_field(t: Scalar, y: EntryState, args: EntryArgs) -> EntryState:
    """d/dt (r, v) for `gnc_jax.integrate`: the inertial form of seed 003 eqs. 1-5.

    ``y`` is an `EntryState` pytree (r, v) and ``args`` an `EntryArgs`; the bank angle in
    ``args`` is held constant over the step (zero-order hold of the guidance command). A
    guidance predictor with a bank profile sigma(v) writes its own field around
    `gravity_acceleration` and `aerodynamic_acceleration`.
    """
    del t  # autonomous: the atmosphere is axially symmetric and co-rotating
    r, v = y
    accel = gravity_acceleration(r, args.earth) + aerodynamic_acceleration(
        r, v, args.bank, args.vehicle, args.earth, args.atmosphere
    )
    return EntryState(v, accel)


def sensed_load_g(
    r: Vector3,
    v: Vector3,
    vehicle: EntryVehicle,
    earth: EarthModel,
    atmosphere: Atmosphere,
) -> Scalar:
    """Aerodynamic (sensed) load N_g = |L + D| / (m g0) = q S sqrt(C_L^2 + C_D^2) / (m g0), in g.

    This is what an accelerometer measures and what seed 003 §2 compares with N_g0 (start of
    guidance) and 0.2 g0 (Kepler phase).
    """
    q = dynamic_pressure(r, v, earth, atmosphere)
    c_r = jnp.sqrt(vehicle.c_l**2 + vehicle.c_d**2)
    return q * vehicle.reference_area_m2 * c_r / (vehicle.mass_kg * G0)


def sutton_graves_heat_rate(
    density: Scalar,
    speed_mps: Scalar,
    nose_radius_m: Scalar,
    k: float = SUTTON_GRAVES_K_EARTH,
) -> Scalar:
    """Stagnation-point convective heat rate q_dot = k sqrt(rho / R_n) V^3, W/m^2.

    Sutton & Graves (NASA TR R-376, 1971) for air: k = 1.7415e-4 kg^0.5/m with rho in kg/m^3,
    R_n in m, V (air-relative) in m/s. Convective only; radiative heating is not modelled.
    """
    return k * jnp.sqrt(density / nose_radius_m) * speed_mps**3


class BankActuatorState(NamedTuple):
    """Bank angle (rad) and bank rate (rad/s) actually flown."""

    bank: Scalar
    bank_rate: Scalar


class BankActuator(eqx.Module):
    """Roll of the bank angle with finite rate and acceleration (reaction-control limits).

    Defaults: 20 deg/s and 10 deg/s^2, typical of the Apollo/Orion reaction control system in
    roll (a 180 deg reversal then takes about 11 s). Angles are not wrapped: a command is reached
    by the straight path in sigma, so a reversal from +60 deg to -60 deg rolls through lift-up.

    Attributes:
        max_rate: rad/s.
        max_acceleration: rad/s^2.
    """

    max_rate: Scalar = eqx.field(default=math.radians(20.0), converter=jnp.asarray)
    max_acceleration: Scalar = eqx.field(default=math.radians(10.0), converter=jnp.asarray)

    def init(self, bank: Scalar) -> BankActuatorState:
        """At rest at ``bank`` (rad)."""
        bank = jnp.asarray(bank, dtype=float)
        return BankActuatorState(bank, jnp.zeros_like(bank))

    def step(self, state: BankActuatorState, command: Scalar, dt: Scalar) -> BankActuatorState:
        """Advance (sigma, sigma_dot) by ``dt`` (s) towards ``command`` (rad).

        The target rate is the largest that can still stop at the command,
        sign(e) min(max_rate, sqrt(2 a_max |e|), |e| / dt) with e = command - sigma (time-optimal
        bang-bang with a braking curve); the rate moves towards it by at most a_max dt, and
        sigma advances with the new rate (semi-implicit Euler). So |sigma_dot| <= max_rate and
        |delta sigma_dot| <= a_max dt hold exactly at every step.
        """
        error = command - state.bank
        # The floor keeps the gradient of sqrt finite when the command is reached (error 0).
        braking = jnp.sqrt(jnp.maximum(2.0 * self.max_acceleration * jnp.abs(error), 1e-30))
        reachable = jnp.minimum(braking, jnp.abs(error) / dt)
        target_rate = jnp.sign(error) * jnp.minimum(self.max_rate, reachable)
        max_change = self.max_acceleration * dt
        rate = state.bank_rate + jnp.clip(target_rate - state.bank_rate, -max_change, max_change)
        return BankActuatorState(state.bank + rate * dt, rate)
