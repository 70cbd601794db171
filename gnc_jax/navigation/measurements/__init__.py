"""Measurement front ends: one abstract contract (``base.py``), one file per member."""

from .base import (
    AbstractMeasurement,
    Exposure,
    Measurement,
    MeasurementSetup,
    measurement_class,
    register_measurement,
)
from .gaussian import GaussianLOSMeasurement
from .image import ImageMeasurement

__all__ = [
    "AbstractMeasurement",
    "Exposure",
    "Measurement",
    "measurement_class",
    "register_measurement",
    "GaussianLOSMeasurement",
    "ImageMeasurement",
    "MeasurementSetup",
]
