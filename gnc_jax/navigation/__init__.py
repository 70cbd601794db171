"""Navigation: camera models and filters."""

from .camera import camera_attitude, los_angles, project, small_rotation
from .centroid import Centroid, extract_centroid, label_components
from .ekf import (
    MeasurementPrediction,
    NavEstimate,
    ekf_update,
    los_model,
    predict_measurement,
    propagate_covariance,
    propagate_state,
    update_los,
)
from .measurements import (
    AbstractMeasurement,
    Exposure,
    GaussianLOSMeasurement,
    ImageMeasurement,
    Measurement,
    MeasurementSetup,
    measurement_class,
    register_measurement,
)
from .render import (
    CameraModel,
    Frame,
    TargetModel,
    choose_binning,
    lambert_sphere_offset,
    render_frame,
    roi_to_tangent,
)

__all__ = [
    "camera_attitude",
    "los_angles",
    "project",
    "small_rotation",
    "NavEstimate",
    "propagate_covariance",
    "propagate_state",
    "update_los",
    "MeasurementPrediction",
    "ekf_update",
    "los_model",
    "predict_measurement",
    "AbstractMeasurement",
    "Exposure",
    "GaussianLOSMeasurement",
    "ImageMeasurement",
    "Measurement",
    "MeasurementSetup",
    "measurement_class",
    "register_measurement",
    "Centroid",
    "extract_centroid",
    "label_components",
    "CameraModel",
    "Frame",
    "TargetModel",
    "choose_binning",
    "lambert_sphere_offset",
    "render_frame",
    "roi_to_tangent",
]
