"""The Earth (gravity and rotation) and the capsule: the parameters of the equations of
motion, SI units."""

import equinox as eqx
import jax.numpy as jnp

from ..._types import Scalar, Vector3
from ...constants import EARTH_EQUATORIAL_RADIUS_M, EARTH_GM_M3S2


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
