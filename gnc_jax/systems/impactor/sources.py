"""The impactor's error sources (seed 000 Table 2) and the draws each owns (:mod:`.draws`)."""

from ..._random import INDEX
from ..base import ErrorSource
from .draws import (
    _ACC_BIAS,
    _ATT_BIAS,
    _BURNS,
    _DELIVERY,
    _IMAGES,
    _KNOW_POS,
    _KNOW_VEL,
    _MISALIGNMENT,
)

_IMAGE = (_IMAGES, INDEX)

ERROR_SOURCES = {
    "delivery": ErrorSource(("errors.delivery_position_km",), (((_DELIVERY,),),), "delivery"),
    "knowledge_position": ErrorSource(
        ("navigation.knowledge_position_km",), (((_KNOW_POS,),),), "initial position knowledge"
    ),
    "knowledge_velocity": ErrorSource(
        ("navigation.knowledge_velocity_mps",), (((_KNOW_VEL,),),), "initial velocity knowledge"
    ),
    "image_processing": ErrorSource(
        ("errors.image_processing_urad",),
        ((_IMAGE, 0, 2), ((*_IMAGE, 1),)),  # the Gaussian front end; a rendered frame's noise
        "centroiding",
    ),
    "attitude_control": ErrorSource(
        ("errors.attitude_control_urad",),
        ((_IMAGE, 2, 5), ((_BURNS,), 1, 4), ((_BURNS,), 5, 8)),  # camera and thrust pointing
        "camera and thrust pointing",
    ),
    "attitude_noise": ErrorSource(
        ("errors.attitude_noise_urad",), ((_IMAGE, 5, 8),), "attitude determination noise"
    ),
    "attitude_bias": ErrorSource(
        ("errors.attitude_bias_urad",), (((_ATT_BIAS,),),), "attitude determination bias"
    ),
    "camera_misalignment": ErrorSource(
        ("errors.camera_misalignment_urad",), (((_MISALIGNMENT,),),), "camera misalignment"
    ),
    "accel_bias": ErrorSource(("errors.accel_bias_ug",), (((_ACC_BIAS,),),), "accelerometer bias"),
    "accel_noise": ErrorSource(
        ("errors.accel_noise_ug",), (((_BURNS,), 8, 14),), "accelerometer noise"
    ),
    "burn_magnitude": ErrorSource(
        ("errors.burn_magnitude_pct",),
        (((_BURNS,), 0, 1), ((_BURNS,), 4, 5)),
        "burn execution magnitude",
    ),
}

SOURCE_GROUPS = {
    "knowledge": ("knowledge_position", "knowledge_velocity"),
    "attitude": ("attitude_control", "attitude_noise", "attitude_bias", "camera_misalignment"),
    "accelerometer": ("accel_bias", "accel_noise"),
}
