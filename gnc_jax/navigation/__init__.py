"""Navigation: camera models and filters."""

from .camera import camera_attitude, los_angles, project, small_rotation
from .centroid import Centroid, extract_centroid, label_components
from .ekf import NavEstimate, propagate_covariance, propagate_state, update_los
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
