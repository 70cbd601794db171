"""The deep-space intercept guidance family (seed 004): its base and the registry of its laws
(``apn``)."""

from typing import ClassVar

from ..base import AbstractGuidanceLaw


class AbstractInterceptGuidance(AbstractGuidanceLaw):
    """Family base of the deep-space intercept laws (seed 004): ``nav`` is a
    :class:`~gnc_jax.guidance.intercept.apn.PNNavigation`, ``ctx`` a
    :class:`~gnc_jax.guidance.intercept.apn.PNGuidanceContext`, ``step`` returns an
    :class:`EngineCommand` whose throttle is the pulse fraction of the step."""

    laws: ClassVar[dict[str, type]] = {}
