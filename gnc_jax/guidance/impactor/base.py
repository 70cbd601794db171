"""The impactor terminal-guidance family: its base, the on-board mission context it reads, and
the registry of its laws (``los``, ``predictive``, ``pn``)."""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from ..._types import Array, Float, Matrix3, Scalar, Vector3
from ...dynamics.impactor import Engine, RelativeDynamics, straight_line_time_to_b_plane
from ...geometry.bplane import b_plane_point_to_inertial
from ...schema import ScenarioError
from ..base import AbstractGuidanceLaw


def nominal_time_of_flight_s(position, velocity) -> float:
    """The nominal time of flight (s) of the straight-line approach to the B-plane
    (:func:`~gnc_jax.dynamics.impactor.straight_line_time_to_b_plane`, any consistent units),
    rounded to 1 us like every mission time derived from it (:func:`mission_time_s`)."""
    return round(straight_line_time_to_b_plane(position, velocity), 6)


def mission_time_s(time_of_flight_s: float, tgo_s: float) -> float:
    """The mission time (s) of the time to go ``tgo_s`` before the nominal impact, rounded to
    1 us: a scheduled event at "t_go = 750 s" then coincides with a burn scheduled at 6450 s
    although 73440 km / 10.2 km/s = 7200.000000000001 s. The scenario checks and the
    simulation's timeline read the same values."""
    return round(time_of_flight_s - tgo_s, 6)


class ImpactorGuidanceContext(eqx.Module):
    """Mission data known on board: B-plane frame, aim points, engine, timing.

    Attributes:
        c_bi: B-plane frame rows (S, T, R), inertial.
        aim_initial_m: aim point (B_T, B_R) before the retarget time, m.
        aim_final_m: aim point after it (seed 000 Table 2: (1, 3) km), m.
        retarget_time_s: mission time at which the aim point changes (t_go = 750 s nominal).
        cutoff_time_s: no burn is commanded from this mission time on.
        engine, mass_kg: nominal engine and initial mass used by the laws.
        dynamics: the on-board model of the differential gravity (predictors).
        dt_s: control step; image_interval_s: navigation image interval.
    """

    c_bi: Matrix3
    aim_initial_m: Float[Array, "2"]
    aim_final_m: Float[Array, "2"]
    retarget_time_s: Scalar
    cutoff_time_s: Scalar
    engine: Engine
    mass_kg: Scalar
    dynamics: RelativeDynamics
    dt_s: float = eqx.field(static=True)
    image_interval_s: float = eqx.field(static=True)

    def aim_b_plane(self, t) -> Float[Array, "2"]:
        return jnp.where(t >= self.retarget_time_s, self.aim_final_m, self.aim_initial_m)

    def aim_point(self, t) -> Vector3:
        """Inertial position of the current aim point (relative to the target), m."""
        return b_plane_point_to_inertial(self.aim_b_plane(t), self.c_bi)


class AbstractImpactorGuidance(AbstractGuidanceLaw):
    """Family base of the impactor terminal-guidance laws: ``nav`` is the filter's
    :class:`~gnc_jax.navigation.ekf.NavEstimate`, ``ctx`` an :class:`ImpactorGuidanceContext`,
    ``plan`` runs after each image's filter update, ``step`` returns an
    :class:`EngineCommand`.

    ``nav_by_component``: the law's ``step`` reads ``nav.r`` and ``nav.v`` through the
    component helpers of :mod:`gnc_jax._numerics` (``sub3``, ``dot3``, ``norm3``, ...), so
    that a loop may hand it the estimate's mean as :class:`~gnc_jax._numerics.V3`
    components (the impactor's reverse-mode control steps do)."""

    laws: ClassVar[dict[str, type]] = {}
    nav_by_component: ClassVar[bool] = False

    @classmethod
    def check(cls, section, config):
        """A change of aim point before the cut-off, or none: after the cut-off no law steers,
        and the miss would be measured from an aim point that is never flown (mission times
        as the simulation's, :func:`mission_time_s`). A law that overrides ``check`` calls it,
        or checks the retarget its own way (the predictive law: a burn at or after it)."""
        g, a = config["guidance"], config["approach"]
        if g["aim_final_km"] == g["aim_initial_km"]:
            return
        tof = nominal_time_of_flight_s(a["position_km"], a["velocity_kmps"])
        if not mission_time_s(tof, g["retarget_tgo_s"]) < mission_time_s(tof, g["cutoff_tgo_s"]):
            raise ScenarioError(
                f"guidance.retarget_tgo_s: {g['retarget_tgo_s']:g} s is not more than "
                f"guidance.cutoff_tgo_s = {g['cutoff_tgo_s']:g} s: the aim point would change "
                f"after the cut-off and never be flown; allowed: ({g['cutoff_tgo_s']:g}, "
                f"{tof:g}) s, or aim_final_km equal to aim_initial_km"
            )
