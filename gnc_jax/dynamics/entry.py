"""Point-mass (3-DOF) atmospheric entry over a rotating Earth with J2 (seed 003 §1).

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

Layout: the physics is written once, on vectors given as their three scalar components
(:class:`EntryStateXYZ`); the functions on ``(3,)`` arrays (:class:`EntryState`) wrap it. Under
``vmap`` a component is one contiguous array over the runs, so the closed loop's inner loops,
which carry an :class:`EntryStateXYZ`, vectorise across runs: a ``(3,)`` vector becomes a
``(runs, 3)`` array whose dot and cross products are strided slices and reductions that cut
XLA's CPU fusions (measured: an RK4 step of the vector form costs about twice the component
form, ``benchmarks/capsule.py``).
"""

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._types import Array, Float, Scalar, Vector3
from ..constants import EARTH_EQUATORIAL_RADIUS_M, EARTH_GM_M3S2, G0_MPS2
from .atmosphere import Atmosphere

G0 = G0_MPS2  # m/s^2, standard gravity: the unit of the sensed load N_g
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

    mu: Scalar = eqx.field(default=EARTH_GM_M3S2, converter=jnp.asarray)
    equatorial_radius_m: Scalar = eqx.field(
        default=EARTH_EQUATORIAL_RADIUS_M, converter=jnp.asarray
    )
    j2: Scalar = eqx.field(default=1.08262668e-3, converter=jnp.asarray)
    rotation_rate: Scalar = eqx.field(default=7.2921159e-5, converter=jnp.asarray)

    def angular_velocity(self) -> Vector3:
        """omega_E as an ECI vector, rad/s."""
        return jnp.array([0.0, 0.0, 1.0]) * self.rotation_rate


class EntryVehicle(eqx.Module):
    """Capsule parameters (what a dispersion draws), SI units.

    Defaults: mass and reference area from seed 003 §4.1 (9000 kg, 22 m^2). The seed gives no
    aerodynamics; the skip-entry scenario takes L/D = 0.3 (an Apollo/Orion-class capsule at
    trim), here as
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


Components = tuple[Scalar, Scalar, Scalar]
"""A vector as its three ECI components (scalars; arrays over the runs under ``vmap``)."""

Vec = Components | Vector3
"""Either layout: the physics below is written once for both."""


class EntryStateXYZ(NamedTuple):
    """The ECI state as scalar components: position ``r`` (m) and velocity ``v`` (m/s), each a
    :data:`Components` tuple. The layout of the closed loop's inner loops (see the module
    docstring); :func:`to_xyz` and :func:`from_xyz` convert."""

    r: Components
    v: Components


def to_xyz(y: "EntryState") -> EntryStateXYZ:
    return EntryStateXYZ((y.r[0], y.r[1], y.r[2]), (y.v[0], y.v[1], y.v[2]))


def from_xyz(y: EntryStateXYZ) -> "EntryState":
    return EntryState(jnp.stack(y.r), jnp.stack(y.v))


# Vector algebra on either layout (resolved at trace time by the Python type).
def _dot(a: Vec, b: Vec) -> Scalar:
    if isinstance(a, tuple):
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    return jnp.dot(a, b)


def _cross(a: Vec, b: Vec) -> Vec:
    if isinstance(a, tuple):
        return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    return jnp.cross(a, b)


def _scaled(k, a: Vec) -> Vec:
    return tuple(k * ai for ai in a) if isinstance(a, tuple) else k * a


def _combine(k1, a: Vec, k2, b: Vec) -> Vec:
    """k1 a + k2 b."""
    if isinstance(a, tuple):
        return tuple(k1 * ai + k2 * bi for ai, bi in zip(a, b))
    return k1 * a + k2 * b


def _plus_z(a: Vec, s) -> Vec:
    """a + s z_hat."""
    if isinstance(a, tuple):
        return (a[0], a[1], a[2] + s)
    return a + s * jnp.array([0.0, 0.0, 1.0])


def _inverse_norm(a: Vec) -> Scalar:
    # 1/|a| with a floor, so that a zero vector's unit vector is zeros instead of NaN. The
    # floor (not a select after the rsqrt) keeps the expensive rsqrt the last operation:
    # XLA's CPU fusion then reads it once instead of recomputing the chain that feeds a
    # select in every consumer (measured: an RK4 step of this field 2.5x slower with selects).
    return jax.lax.rsqrt(jnp.maximum(_dot(a, a), 1e-300))


def _unit(x: Vec) -> Vec:
    return _scaled(_inverse_norm(x), x)


def _earth_relative(r: Vec, v: Vec, earth: "EarthModel") -> Vec:
    w = earth.rotation_rate
    if isinstance(r, tuple):
        return (v[0] + w * r[1], v[1] - w * r[0], v[2])
    return v - jnp.cross(earth.angular_velocity(), r)


def earth_relative_velocity_xyz(r: Components, v: Components, earth: "EarthModel") -> Components:
    """:func:`earth_relative_velocity` on components, m/s."""
    return _earth_relative(r, v, earth)


def _gravity(r: Vec, earth: "EarthModel", inv_r) -> Vec:
    """Seed 003 eq. 3 (see :func:`gravity_acceleration`), with ``inv_r`` = 1/|r|."""
    sin_lat = r[2] * inv_r
    mu_r2 = earth.mu / _dot(r, r)
    j2_term = earth.j2 * (earth.equatorial_radius_m * inv_r) ** 2
    g_r = -mu_r2 * (1.0 + 1.5 * j2_term * (1.0 - 5.0 * sin_lat**2))
    g_omega = -3.0 * mu_r2 * j2_term * sin_lat
    return _plus_z(_scaled(g_r * inv_r, r), g_omega)


def _lift_up(r_hat: Vec, v_hat: Vec) -> Vec:
    """The component of r_hat perpendicular to v_hat, normalised ("lift up")."""
    up = _combine(1.0, r_hat, -_dot(r_hat, v_hat), v_hat)
    return _scaled(_inverse_norm(up), up)


def _aerodynamic(r_hat: Vec, v_rel: Vec, density, vehicle: "EntryVehicle", cos_bank, sin_bank):
    """Drag along -v_rel and lift (bank from its cosine and sine; ``sin_bank=None``: in the
    vertical plane, no lateral component) per unit mass, m/s^2."""
    u2 = _dot(v_rel, v_rel)
    q_s_over_m = 0.5 * density * u2 * vehicle.reference_area_m2 / vehicle.mass_kg
    v_hat = _scaled(jax.lax.rsqrt(jnp.maximum(u2, 1e-300)), v_rel)
    up = _lift_up(r_hat, v_hat)
    k_lift = q_s_over_m * vehicle.c_l
    lift = _scaled(k_lift * cos_bank, up)
    if sin_bank is not None:
        lift = _combine(1.0, lift, k_lift * sin_bank, _cross(v_hat, up))
    return _combine(-q_s_over_m * vehicle.c_d, v_hat, 1.0, lift)


def _acceleration(r: Vec, v: Vec, vehicle, earth, atmosphere, cos_bank, sin_bank, density):
    """Gravity plus aerodynamics, m/s^2, and the density used (looked up if ``None``)."""
    inv_r = _inverse_norm(r)
    if density is None:
        density = atmosphere.density(_dot(r, r) * inv_r - earth.equatorial_radius_m)
    aero = _aerodynamic(
        _scaled(inv_r, r), _earth_relative(r, v, earth), density, vehicle, cos_bank, sin_bank
    )
    return _combine(1.0, _gravity(r, earth, inv_r), 1.0, aero), density


def entry_acceleration_xyz(
    y: EntryStateXYZ,
    vehicle: "EntryVehicle",
    earth: "EarthModel",
    atmosphere: Atmosphere,
    cos_bank,
    sin_bank=None,
    density=None,
) -> tuple[Components, Scalar]:
    """Gravity (J2) plus lift and drag per unit mass, m/s^2, and the density it used: the
    right-hand side of :func:`entry_vector_field` on components, with the bank given by its
    cosine and sine (``sin_bank=None``: lift in the vertical plane, as the guidance's
    predictor flies). ``density`` (kg/m^3) may be given when the caller has it at ``y``
    already (evaluated at the end of its previous step), which saves the table lookup."""
    return _acceleration(y.r, y.v, vehicle, earth, atmosphere, cos_bank, sin_bank, density)


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


def _xyz(x: Vector3) -> Components:
    return (x[0], x[1], x[2])


def gravity_acceleration(r: Vector3, earth: EarthModel) -> Vector3:
    """Gravity with J2, seed 003 eq. 3: g = g_r r_hat + g_omega omega_hat, m/s^2.

    g_r = -mu/r^2 [1 + 3/2 J2 (a_e/r)^2 (1 - 5 sin^2 phi)],
    g_omega = -3 mu/r^2 J2 (a_e/r)^2 sin phi, with phi the geocentric latitude and omega_hat
    the spin axis (ECI z).
    """
    return _gravity(r, earth, _inverse_norm(r))


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
    up = _lift_up(_unit(r), v_hat)
    return jnp.cos(bank) * up + jnp.sin(bank) * jnp.cross(v_hat, up)


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
    density = atmosphere.density(altitude(r, earth))
    v_rel = _earth_relative(r, v, earth)
    return _aerodynamic(_unit(r), v_rel, density, vehicle, jnp.cos(bank), jnp.sin(bank))


def entry_vector_field(t: Scalar, y: EntryState, args: EntryArgs) -> EntryState:
    """d/dt (r, v) for `gnc_jax.integrate`: the inertial form of seed 003 eqs. 1-5.

    ``y`` is an `EntryState` pytree (r, v) and ``args`` an `EntryArgs`; the bank angle in
    ``args`` is held constant over the step (zero-order hold of the guidance command). A
    guidance predictor with a bank profile sigma(v) writes its own field around
    `entry_acceleration_xyz`. `entry_vector_field_xyz` is the same field on components.
    """
    del t  # autonomous: the atmosphere is axially symmetric and co-rotating
    a = args
    accel, _ = _acceleration(
        y.r, y.v, a.vehicle, a.earth, a.atmosphere, jnp.cos(a.bank), jnp.sin(a.bank), None
    )
    return EntryState(y.v, accel)


def entry_vector_field_xyz(t: Scalar, y: EntryStateXYZ, args: EntryArgs) -> EntryStateXYZ:
    """`entry_vector_field` on an :class:`EntryStateXYZ` (the layout of batched loops)."""
    del t
    a = args
    accel, _ = entry_acceleration_xyz(
        y, a.vehicle, a.earth, a.atmosphere, jnp.cos(a.bank), jnp.sin(a.bank)
    )
    return EntryStateXYZ(y.v, accel)


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
    roll (a 180 deg reversal then takes about 11 s). ``way`` chooses the way round of a
    reversal (the angle flown is kept in (-180, 180] deg but with ``"through_lift_up"``):

    - ``"shortest"`` (the default): to a lift-down command (beyond 90 deg) the shorter way
      round, which never crosses lift-up to reach lift-down; to a lift-up command through
      lift-up (the straight path in sigma), a roll under way keeping its way round when the
      command changes.
    - ``"lift_down_pairs"``: the straight path in sigma (through lift-up), except between two
      lift-down banks, through lift-down; a roll under way keeps its way round (kept for
      comparison).
    - ``"through_lift_up"``: always the straight path.

    Measured: rolling a lift-down reversal through lift-up lofts a capsule entering shallow
    (-5.6 deg) out of the atmosphere (5 of 256 runs); rolling every reversal the shorter way
    round sinks it at the bottom of its first dip when the bank is near 90 deg (6 of 1000
    nominal runs). With ``"lift_down_pairs"``, reversals commanded in quick succession at
    the bottom of a shallow (-5.3 deg) entry's dip, a roll under way keeping its way, turned
    the capsule through lift-up a whole revolution and lofted it out (the first roll from a
    lift-up hold to a lift-down command crossed lift-up too).

    Attributes:
        max_rate: rad/s.
        max_acceleration: rad/s^2.
        way: ``"shortest"``, ``"lift_down_pairs"`` or ``"through_lift_up"`` (static).
    """

    max_rate: Scalar = eqx.field(default=math.radians(20.0), converter=jnp.asarray)
    max_acceleration: Scalar = eqx.field(default=math.radians(10.0), converter=jnp.asarray)
    way: str = eqx.field(default="shortest", static=True)

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
        if self.way != "through_lift_up":
            # Two ways round differ when |error| > pi: the straight one (through lift-up) and
            # the wrapped one (through lift-down).
            wrapped = jnp.remainder(error + math.pi, 2.0 * math.pi) - math.pi
            command_down = jnp.abs(command) > 0.5 * math.pi
            rolling = jnp.abs(state.bank_rate) > 0.5 * self.max_rate
            keep = state.bank_rate * wrapped > 0.0  # the roll under way goes the wrapped way
            if self.way == "shortest":
                shorter = jnp.abs(wrapped) < jnp.abs(error)  # a tie goes straight
                way = (command_down & shorter) | (~command_down & rolling & keep)
            else:  # lift_down_pairs
                down = command_down & (jnp.abs(state.bank) > 0.5 * math.pi)
                way = jnp.where(rolling, keep, down)
            error = jnp.where(way, wrapped, error)
        # The floor keeps the gradient of sqrt finite when the command is reached (error 0).
        braking = jnp.sqrt(jnp.maximum(2.0 * self.max_acceleration * jnp.abs(error), 1e-30))
        reachable = jnp.minimum(braking, jnp.abs(error) / dt)
        target_rate = jnp.sign(error) * jnp.minimum(self.max_rate, reachable)
        max_change = self.max_acceleration * dt
        rate = state.bank_rate + jnp.clip(target_rate - state.bank_rate, -max_change, max_change)
        bank = state.bank + rate * dt
        if self.way != "through_lift_up":  # the angle flown in (-pi, pi]
            bank = jnp.where(bank > math.pi, bank - 2.0 * math.pi, bank)
            bank = jnp.where(bank <= -math.pi, bank + 2.0 * math.pi, bank)
        return BankActuatorState(bank, rate)
