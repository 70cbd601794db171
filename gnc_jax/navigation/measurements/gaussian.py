"""Gaussian LOS front end: the true tangent-plane angles plus white image-processing noise.

z = (x_c/z_c, y_c/z_c) of the true LOS in the true camera frame + sigma w, w ~ N(0, I)
(seed 000 Table 2: sigma = 10 urad image processing). The planar intercept keeps every error in
the orbit plane: its out-of-plane angle is exact (``planar``).
"""

import equinox as eqx
import jax.numpy as jnp

from ..._types import Array, Float, PRNGKeyArray, Scalar
from ..camera import los_angles
from ..ekf import MeasurementPrediction, NavEstimate
from .base import (
    AbstractMeasurement,
    Exposure,
    Measurement,
    MeasurementSetup,
    register_measurement,
)


@register_measurement("noise")
class GaussianLOSMeasurement(AbstractMeasurement):
    """True LOS angles + Gaussian noise of ``sigma_rad`` (rad, 1-sigma per axis).

    ``planar`` (static): zero noise on the second (out-of-plane) angle.
    """

    sigma_rad: Scalar
    planar: bool = eqx.field(static=True, default=False)

    def __call__(
        self,
        exposure: Exposure,
        nav: NavEstimate,
        predicted: MeasurementPrediction,
        noise: Float[Array, "2"],
        key: PRNGKeyArray,
    ) -> Measurement:
        z_true = los_angles(exposure.c_true, exposure.los_m)
        if self.planar:
            noise = noise * jnp.array([1.0, 0.0])  # the out-of-plane angle is exactly zero
        z = z_true + self.sigma_rad * noise
        return Measurement(z, jnp.ones((), bool), z_true)

    @classmethod
    def from_setup(cls, setup: MeasurementSetup) -> "GaussianLOSMeasurement":
        return cls(setup.image_processing_rad)


__all__ = ["GaussianLOSMeasurement"]
