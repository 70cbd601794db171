"""Interface of the impactor terminal-guidance laws.

A law is an ``equinox.Module`` whose tunable gains are array leaves; its evolving state is a
small NamedTuple. The simulator calls

* ``init(nav, ctx) -> state`` once,
* ``plan(state, nav, t, ctx) -> state`` at the image (navigation-update) rate, right after the
  filter has taken the image at time ``t``;
* ``step(state, nav, t, ctx) -> (EngineCommand, state)`` at the control rate.

``nav`` is the filter's :class:`~gnc_jax.navigation.ekf.NavEstimate`; ``ctx`` the mission data a
law may use (:class:`ImpactorGuidanceContext`). Everything is written for one trajectory.
"""

import abc
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from .._types import Array, Float, Matrix3, Scalar, Vector3
from ..dynamics.impactor import Engine, RelativeDynamics
from ..geometry.bplane import b_plane_point_to_inertial


class EngineCommand(NamedTuple):
    throttle: Scalar  # fraction of the control step the engine fires, in [0, 1]
    direction: Vector3  # commanded thrust direction, unit vector, inertial


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


def safe_unit(v: Vector3, fallback: Vector3) -> Vector3:
    """``v/|v|``, or ``fallback`` when ``v`` is (near) zero, with finite gradients either way."""
    n2 = jnp.dot(v, v)
    ok = n2 > 1e-30
    n = jnp.sqrt(jnp.where(ok, n2, 1.0))
    return jnp.where(ok, v / n, fallback)


class AbstractImpactorGuidance(eqx.Module):
    """Base class of impactor guidance laws (see the module docstring for the protocol)."""

    @abc.abstractmethod
    def init(self, nav, ctx: ImpactorGuidanceContext): ...

    def plan(self, state, nav, t, ctx: ImpactorGuidanceContext):
        return state

    @abc.abstractmethod
    def step(self, state, nav, t, ctx: ImpactorGuidanceContext): ...
