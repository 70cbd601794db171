"""The entry state, as ``(3,)`` vectors (:class:`EntryState`) or as scalar components
(:class:`EntryStateXYZ`), the arguments of the vector field and the entry conditions."""

from typing import NamedTuple

import jax.numpy as jnp

from ..._types import Scalar, Vector3
from ..atmosphere import Atmosphere
from .models import EarthModel, EntryVehicle


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
"""Either layout: the physics (``vectors``, ``forces``) is written once for both."""


class EntryStateXYZ(NamedTuple):
    """The ECI state as scalar components: position ``r`` (m) and velocity ``v`` (m/s), each a
    :data:`Components` tuple. The layout of the closed loop's inner loops (see
    :mod:`gnc_jax.dynamics.entry`); :func:`to_xyz` and :func:`from_xyz` convert."""

    r: Components
    v: Components


def to_xyz(y: "EntryState") -> EntryStateXYZ:
    return EntryStateXYZ((y.r[0], y.r[1], y.r[2]), (y.v[0], y.v[1], y.v[2]))


def from_xyz(y: EntryStateXYZ) -> "EntryState":
    return EntryState(jnp.stack(y.r), jnp.stack(y.v))


def _xyz(x: Vector3) -> Components:
    return (x[0], x[1], x[2])
