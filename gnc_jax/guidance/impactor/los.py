"""LOS switching-curve terminal guidance (seed 000 §3) — "the impactor law".

The engine opens when the LOS rate |omega| reaches the switching curve omega_open of the miss
tolerance rho_max = k1 sqrt(E^2 + F^2) and closes at omega_close of rho_min = k2 sqrt(E^2 + F^2),
with E, F the B-plane error-ellipse semi-axes of the navigation covariance mapped to impact.
Between the curves the engine keeps its previous state (hysteresis, §3.3). Thrust is
perpendicular to the relative velocity in the plane of rho and rho_dot (eq. 19), with the sign
that reduces |omega|.
"""

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._numerics import cross3, dot3, norm3, safe_norm, sub3
from ..._types import Array, Float, Scalar
from ...geometry.ellipse import b_plane_position_covariance, mean_position_error
from ...geometry.los import los_rate, range_rate, zero_effort_miss
from ...params import param
from ...schema import ScenarioError
from ..base import EngineCommand, register_law, safe_unit
from ..schedule import check_schedules, scheduled
from ..trigger import schmitt_trigger
from .base import AbstractImpactorGuidance, ImpactorGuidanceContext


def switching_curve(rho, rho_dot_scalar, rho_limit):
    """LOS rate at which the unforced miss equals ``rho_limit`` (seed 000 eq. 20), rad/s.

    omega = -rho_limit rho_dot / sqrt(rho^4 - rho_limit^2 rho^2). Infinite when rho <= rho_limit
    (no LOS rate can produce that miss any more).
    """
    arg = rho**4 - rho_limit**2 * rho**2
    ok = arg > 0.0
    return jnp.where(ok, -rho_limit * rho_dot_scalar / jnp.sqrt(jnp.where(ok, arg, 1.0)), jnp.inf)


def _resolution_per_tgo(ctx: ImpactorGuidanceContext):
    """Half the miss one control step's burn moves, per second of time to go, m/s."""
    return 0.5 * ctx.engine.thrust_n / ctx.mass_kg * ctx.dt_s


def miss_limits(k1, k2, sigma_b, rho_n, nav, ctx: ImpactorGuidanceContext):
    """``(rho_min, rho_max)``: the shut-off and opening miss tolerances, k2 sigma_B and
    k1 sigma_B (seed 000 §3.3), with sigma_B no smaller than the shut-off tolerance at half
    the miss one control step's burn moves needs.

    One control step of thrust changes the predicted miss by about (T/m) dt t_go; a shut-off
    tolerance below half of that cannot be met by whole steps, and with perfect navigation
    (sigma_B -> 0) the engine would never close. The floor is on sigma_B, not on each
    tolerance, so that it keeps the hysteresis band k1/k2: flooring both tolerances at the
    same value would close the band, and with an accurate sensor the engine would then toggle
    every few steps until the propellant is gone. In the papers' scenarios the floor binds only
    near impact (69 of 2000 deep-impact-los runs); elsewhere the tolerances are exactly
    k2 sigma_B and k1 sigma_B.
    """
    t_go = rho_n / safe_norm(nav.v)
    resolution = _resolution_per_tgo(ctx) * t_go
    sigma = jnp.maximum(sigma_b, resolution / k2)
    return k2 * sigma, k1 * sigma


def _hard_switch(rho, rho_dot, state, nav, k1, k2, ctx: ImpactorGuidanceContext):
    """The hard switch of :meth:`LOSSwitchingCurveGuidance.step` without a square root.

    |omega| >= omega_open (eq. 20) holds exactly when rho^2 > rho_l^2 and either the range is
    opening (omega_open <= 0) or |rho x rho_dot|^2 (rho^2 - rho_l^2) >= rho_l^2
    (rho . rho_dot)^2, both sides of the comparison multiplied out by positive factors (and
    likewise for omega_close; rho_l^2 is built from squares as :func:`miss_limits` builds
    rho_l). The same decisions as comparing the rates (up to the last bit's rounding at an
    exact tie), for a third of the law step's square roots and divisions: the step runs at
    every control step of every run, so it is a fifth of the closed loop's time.
    """
    rr = dot3(rho, rho)
    qv = dot3(rho, rho_dot)
    o = cross3(rho, rho_dot)
    oo = dot3(o, o)
    vv = dot3(nav.v, nav.v)
    c = _resolution_per_tgo(ctx)
    resolution2 = c * c * rr / vv
    s2 = jnp.maximum(state.sigma_b_m * state.sigma_b_m, resolution2 / (k2 * k2))
    close2 = k2 * k2 * s2
    open2 = k1 * k1 * s2
    closing = qv < 0.0
    opens = (rr > open2) & (~closing | (oo * (rr - open2) >= open2 * (qv * qv)))
    closes = (rr <= close2) | (
        closing & (oo * (rr - close2) <= close2 * (qv * qv))
        | (~closing & (oo == 0.0) & (qv == 0.0))
    )
    return jnp.where(opens, 1.0, jnp.where(closes, 0.0, state.engine_on))


class LOSGuidanceState(NamedTuple):
    engine_on: Scalar  # 0/1 (hard) or in [0, 1] (relaxed)
    sigma_b_m: Scalar  # sqrt(E^2 + F^2) at the last image, m
    omega: Scalar  # |omega| at the last step, rad/s (diagnostics, Fig. 3)
    omega_open: Scalar
    omega_close: Scalar


@register_law("los")
class LOSSwitchingCurveGuidance(AbstractImpactorGuidance):
    """Seed 000 LOS law. Gains ``k1``, ``k2`` (paper: 4, 1) are differentiable leaves.

    With ``relaxed=True`` the hysteresis switch (:func:`~gnc_jax.guidance.trigger.schmitt_trigger`
    on |omega| with levels omega_open, omega_close) is replaced by its smooth relaxation at
    temperature ``T``, so gradients with respect to k1 and k2 exist; it reduces to the hard
    logic as T -> 0. Evaluation uses the hard logic.
    """

    k1: Scalar = param(
        4.0,
        lo=0.0,
        lo_open=True,
        hi=100.0,
        doc="miss tolerance rho_max = k1 sqrt(E^2+F^2)",
        tunable=True,
    )
    k2: Scalar = param(
        1.0,
        lo=0.0,
        lo_open=True,
        hi=100.0,
        doc="shut-off rho_min = k2 sqrt(E^2+F^2); k2 <= k1",
        tunable=True,
    )
    k1_schedule: Float[Array, " n"] = param(
        [],
        lo=0.0,
        lo_open=True,
        hi=100.0,
        doc="k1 at the breakpoints schedule_tgo_s, linear between; [] = the constant k1",
        tunable=True,
    )
    k2_schedule: Float[Array, " n"] = param(
        [],
        lo=0.0,
        lo_open=True,
        hi=100.0,
        doc="k2 at the breakpoints schedule_tgo_s, linear between; [] = the constant k2",
        tunable=True,
    )
    schedule_tgo_s: Float[Array, " n"] = param(
        [],
        lo=0.0,
        units="s",
        doc="time-to-go breakpoints (rho / |v|) of k1_schedule and k2_schedule, increasing",
    )
    temperature: Scalar = param(
        0.05, lo=0.0, lo_open=True, hi=10.0, doc="temperature of the relaxed switch (gradients)"
    )
    relaxed: bool = eqx.field(static=True, default=False)

    ordered_gains = (("k1", "k2"),)
    nav_by_component = True
    schedules = {"k1_schedule": "k1", "k2_schedule": "k2"}  # schedule -> the gain it replaces
    schedule_breakpoints = "schedule_tgo_s"

    @classmethod
    def check(cls, section, config):
        super().check(section, config)
        check_schedules(section, cls.schedule_breakpoints, cls.schedules, "guidance.los")
        k1 = np.asarray(section["k1_schedule"] or [section["k1"]], float)
        k2 = np.asarray(section["k2_schedule"] or [section["k2"]], float)
        k1, k2 = np.broadcast_arrays(k1, k2)
        if np.any(k2 > k1):
            i = int(np.argmax(k2 > k1))
            name = "k2_schedule" if section["k2_schedule"] else "k2"
            raise ScenarioError(
                f"guidance.los.{name}: {k2[i]:g} > k1 = {k1[i]:g} (breakpoint {i}); "
                "allowed: 0 < k2 <= k1 (at every breakpoint of a schedule)"
            )

    def gains_at(self, t_go):
        """``(k1, k2)`` at time to go ``t_go`` (s): the schedules, or the constant gains."""
        k1 = scheduled(self.k1, self.k1_schedule, self.schedule_tgo_s, t_go)
        k2 = scheduled(self.k2, self.k2_schedule, self.schedule_tgo_s, t_go)
        return k1, k2

    def describe(self) -> str:
        k1 = "scheduled" if self.k1_schedule.shape[0] else f"{float(self.k1):g}"
        k2 = "scheduled" if self.k2_schedule.shape[0] else f"{float(self.k2):g}"
        return f"LOS switching curves, k1 = {k1}, k2 = {k2}"

    def state_curves(self, state_trace) -> dict:
        """|omega| against its switching curves (seed 000 Fig. 3), rad/s."""
        return {
            "|ω| (navigation), rad/s": state_trace.omega,
            "ω_open (k1), rad/s": state_trace.omega_open,
            "ω_close (k2), rad/s": state_trace.omega_close,
        }

    def init(self, nav, ctx: ImpactorGuidanceContext) -> LOSGuidanceState:
        z = jnp.zeros(())
        return self.plan(LOSGuidanceState(z, z, z, z, z), nav, 0.0, ctx)

    def plan(self, state, nav, t, ctx: ImpactorGuidanceContext) -> LOSGuidanceState:
        # Error ellipse of the predicted impact point (eqs. 8-11), t_go = rho / |V_inf| (eq. 9).
        rho = ctx.aim_point(t) - nav.r
        t_go = norm3(rho) / norm3(nav.v)
        d = b_plane_position_covariance(nav.p, t_go, ctx.c_bi)
        return state._replace(sigma_b_m=mean_position_error(d))

    def step(self, state, nav, t, ctx: ImpactorGuidanceContext):
        rho = sub3(ctx.aim_point(t), nav.r)
        rho_dot = -nav.v  # the target is the origin; the aim point is fixed to it
        rho_n = norm3(rho)
        rdot = range_rate(rho, rho_dot)
        omega = norm3(los_rate(rho, rho_dot))
        k1, k2 = self.gains_at(rho_n / norm3(nav.v))  # t_go as the error ellipse's (eq. 9)
        rho_close, rho_open = miss_limits(k1, k2, state.sigma_b_m, rho_n, nav, ctx)
        w_open = switching_curve(rho_n, rdot, rho_open)
        w_close = switching_curve(rho_n, rdot, rho_close)
        if self.relaxed:
            on = schmitt_trigger(omega, state.engine_on, w_open, w_close, self.temperature)
        else:
            on = _hard_switch(rho, rho_dot, state, nav, k1, k2, ctx)
        on = jnp.where(t < ctx.cutoff_time_s, on, 0.0)
        # Eq. 19 up to sign: the zero-effort-miss direction -rho_dot x (rho_dot x rho) points
        # from the impactor to the closest-approach offset, so thrusting along it reduces |omega|.
        direction = safe_unit(zero_effort_miss(rho, rho_dot), ctx.c_bi[1])
        new_state = LOSGuidanceState(on, state.sigma_b_m, omega, w_open, w_close)
        return EngineCommand(on, direction), new_state
