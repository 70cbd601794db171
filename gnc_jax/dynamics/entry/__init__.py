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

The parts: ``models`` (the Earth and the vehicle), ``state`` (the state's two layouts and the
entry conditions), ``vectors`` (vector algebra on either layout), ``conditions`` (Earth-relative
quantities), ``forces`` (gravity, lift, drag, the vector field, load and heating) and
``actuator`` (the bank-angle actuator).
"""

from .actuator import BankActuator, BankActuatorState
from .conditions import (
    altitude,
    earth_relative_velocity,
    entry_conditions_from_state,
    entry_state_from_conditions,
    flight_path_angle,
    geocentric_latitude_longitude,
)
from .forces import (
    G0,
    SUTTON_GRAVES_K_EARTH,
    aerodynamic_acceleration,
    dynamic_pressure,
    earth_relative_velocity_xyz,
    entry_acceleration_xyz,
    entry_vector_field,
    entry_vector_field_xyz,
    gravity_acceleration,
    lift_direction,
    sensed_load_g,
    sutton_graves_heat_rate,
)
from .models import EarthModel, EntryVehicle
from .state import (
    Components,
    EntryArgs,
    EntryConditions,
    EntryState,
    EntryStateXYZ,
    Vec,
    from_xyz,
    to_xyz,
)

__all__ = [
    "G0",
    "SUTTON_GRAVES_K_EARTH",
    "EarthModel",
    "EntryVehicle",
    "EntryState",
    "EntryArgs",
    "EntryConditions",
    "Components",
    "Vec",
    "EntryStateXYZ",
    "to_xyz",
    "from_xyz",
    "earth_relative_velocity_xyz",
    "entry_acceleration_xyz",
    "altitude",
    "earth_relative_velocity",
    "flight_path_angle",
    "geocentric_latitude_longitude",
    "entry_state_from_conditions",
    "entry_conditions_from_state",
    "gravity_acceleration",
    "dynamic_pressure",
    "lift_direction",
    "aerodynamic_acceleration",
    "entry_vector_field",
    "entry_vector_field_xyz",
    "sensed_load_g",
    "sutton_graves_heat_rate",
    "BankActuatorState",
    "BankActuator",
]
