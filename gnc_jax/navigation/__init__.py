"""Navigation: camera models and filters."""

from .camera import camera_attitude, los_angles, project, small_rotation
from .ekf import NavEstimate, propagate_covariance, propagate_state, update_los

__all__ = [
    "camera_attitude",
    "los_angles",
    "project",
    "small_rotation",
    "NavEstimate",
    "propagate_covariance",
    "propagate_state",
    "update_los",
]
