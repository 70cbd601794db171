"""The equations of motion: gravity with J2 (seed 003 eq. 3), lift and drag, the vector
field on either layout, the sensed load and the stagnation-point heat rate."""

import jax
import jax.numpy as jnp

from ..._types import Scalar, Vector3
from ...constants import G0_MPS2
from ..atmosphere import Atmosphere
from .conditions import altitude, earth_relative_velocity
from .models import EarthModel, EntryVehicle
from .state import Components, EntryArgs, EntryState, EntryStateXYZ, Vec
from .vectors import _combine, _cross, _dot, _inverse_norm, _plus_z, _scaled, _unit

G0 = G0_MPS2  # m/s^2, standard gravity: the unit of the sensed load N_g
SUTTON_GRAVES_K_EARTH = 1.7415e-4  # kg^0.5/m: Sutton-Graves constant for air, SI units


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
    right-hand side of the velocity (see :mod:`gnc_jax.dynamics.entry` for the sign convention).
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
