"""The measurement family: one abstract front end, one registry (``navigation.measurement``).

A measurement is an ``equinox.Module`` that turns one image's truth into what the filter
takes: the target's tangent-plane angles z (rad, the camera model of
:mod:`gnc_jax.navigation.camera`) and whether they are usable. The simulator calls it once per
image with

* ``exposure``: the true LOS and the true and believed camera attitudes (:class:`Exposure`);
* ``nav``: the navigation estimate before the update;
* ``predicted``: the filter's :class:`~gnc_jax.navigation.ekf.MeasurementPrediction` (the
  predicted angles and the innovation covariance, where a front end places its region of
  interest);
* ``noise``: two standard normals the simulator drew for this image (its random-stream
  layout), ``key``: a key for front ends that draw more (the renderer).

A front end is built from a :class:`MeasurementSetup`: the scenario's camera, target and
image-processing error in SI units, which the system builds from its declared parameters.

A front end joins the family by :func:`register_measurement`; a scenario chooses one by name::

    @register_measurement("image")
    class ImageMeasurement(AbstractMeasurement): ...
"""

import abc
from typing import ClassVar, NamedTuple

import equinox as eqx

from ..._types import Array, Bool, Float, Matrix3, PRNGKeyArray, Scalar, Vector3
from ..ekf import MeasurementPrediction, NavEstimate
from ..render import CameraModel, TargetModel


class Exposure(NamedTuple):
    """The truth of one image."""

    los_m: Vector3  # true LOS from the impactor to the target (-r), inertial, m
    c_true: Matrix3  # true camera attitude C_cI (rows x_c, y_c, z_c)
    c_est: Matrix3  # the camera attitude the navigation believes


class Measurement(NamedTuple):
    """What a front end hands the filter for one image."""

    z: Float[Array, "2"]  # measured tangent-plane angles, rad
    valid: Bool[Array, ""]  # False: no usable measurement (no filter update)
    z_true: Float[Array, "2"]  # true angles in the true camera frame (error statistics), rad


class MeasurementSetup(NamedTuple):
    """What a front end is built from: a scenario's values in SI units."""

    camera: CameraModel  # camera and detector
    target: TargetModel  # the target's shape, orientation and lighting
    image_processing_rad: Scalar  # 1-sigma centroiding error per angle drawn by the truth
    phase_correction: Scalar  # 1.0: remove the predicted centre-of-brightness offset


class AbstractMeasurement(eqx.Module):
    """Base class of the measurement front ends (see the module docstring for the protocol).

    Class attributes set by :func:`register_measurement`: ``measurement_name``, the name a
    scenario chooses it by (``navigation.measurement``).
    """

    measurements: ClassVar[dict[str, type]] = {}
    measurement_name: ClassVar[str] = ""
    # Why the front end's derivatives with respect to the geometry and the draws are not
    # sensitivities (empty: they are). The linearised error budget is then not computed.
    not_differentiable: ClassVar[str] = ""

    @abc.abstractmethod
    def __call__(
        self,
        exposure: Exposure,
        nav: NavEstimate,
        predicted: MeasurementPrediction,
        noise: Float[Array, "2"],
        key: PRNGKeyArray,
    ) -> Measurement: ...

    @classmethod
    def check(cls, config: dict) -> None:
        """Cross-field checks of a validated scenario that only this front end needs; raise
        :class:`~gnc_jax.scenario.ScenarioError` with one line. Default: none."""
        return None

    @classmethod
    @abc.abstractmethod
    def from_setup(cls, setup: MeasurementSetup) -> "AbstractMeasurement":
        """The front end of a scenario, from its SI values."""


def register_measurement(name: str):
    """Class decorator: register a front end under ``name`` (``navigation.measurement``)."""

    def decorate(cls):
        known = AbstractMeasurement.measurements
        if name in known and known[name] is not cls:
            raise ValueError(f"a measurement named {name!r} is already registered")
        known[name] = cls
        cls.measurement_name = name
        return cls

    return decorate


def measurement_class(name: str) -> type:
    """The front end registered under ``name``."""
    try:
        return AbstractMeasurement.measurements[name]
    except KeyError:
        known = ", ".join(sorted(AbstractMeasurement.measurements))
        raise ValueError(f"unknown measurement {name!r}; registered: {known}") from None


__all__ = [
    "AbstractMeasurement",
    "Exposure",
    "Measurement",
    "MeasurementSetup",
    "measurement_class",
    "register_measurement",
]
