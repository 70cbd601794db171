"""The intercept's error sources and the draws each owns (:mod:`.draws`)."""

from ..._random import INDEX
from ..base import ErrorSource
from .draws import _FRONT_END, _IGNITIONS, _IMAGES, _KNOW_POS, _KNOW_VEL

ERROR_SOURCES = {
    "knowledge_position": ErrorSource(
        ("navigation.knowledge_position_km",), (((_KNOW_POS,),),), "initial position knowledge"
    ),
    "knowledge_velocity": ErrorSource(
        ("navigation.knowledge_velocity_mps",), (((_KNOW_VEL,),),), "initial velocity knowledge"
    ),
    "measurement": ErrorSource(
        ("navigation.model",),
        (((_IMAGES, INDEX),), ((_FRONT_END, INDEX),)),
        "LOS measurement noise",
    ),
    "pointing": ErrorSource(("errors.attitude_urad",), (((_IGNITIONS,),),), "thrust pointing"),
}

SOURCE_GROUPS = {"knowledge": ("knowledge_position", "knowledge_velocity")}
