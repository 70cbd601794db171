"""Frames and geometry shared by every system: B-plane, line of sight, error ellipses."""

from .bplane import BPlaneError, b_plane_crossing, b_plane_frame, check_b_plane_frame
from .ellipse import (
    b_plane_position_covariance,
    ellipse_probability,
    error_ellipse,
    map_covariance,
    mean_position_error,
)
from .hyperbola import HyperbolicBPlane, b_plane_hyperbolic, check_hyperbolic_b_plane
from .los import los_frame, los_rate, range_rate, time_to_go, unforced_miss, zero_effort_miss

__all__ = [
    "BPlaneError",
    "b_plane_crossing",
    "b_plane_frame",
    "check_b_plane_frame",
    "b_plane_position_covariance",
    "ellipse_probability",
    "error_ellipse",
    "map_covariance",
    "mean_position_error",
    "los_frame",
    "los_rate",
    "range_rate",
    "time_to_go",
    "unforced_miss",
    "zero_effort_miss",
    "HyperbolicBPlane",
    "b_plane_hyperbolic",
    "check_hyperbolic_b_plane",
]
