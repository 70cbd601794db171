"""Proportional navigation with Schmitt-triggered firing for the impactor — a textbook law to
set against seed 000's switching curves on the same engine, camera and filter.

Line of sight from the impactor to the aim point, rho = aim - r_hat, rho_dot = -v_hat (the aim
point is fixed to the target). The PN command (Zarchan, "Tactical and Strategic Missile
Guidance", ch. 2) is

    a_cmd = N V_c (omega x u),   omega = rho x rho_dot / |rho|^2,   V_c = -rho . rho_dot / |rho|,

perpendicular to the LOS u = rho/|rho|; its magnitude equals N ZEM_perp / t_go^2. The
impactor's engine has one thrust level, hundreds of times the command: it delivers the command
by pulse-width modulation (the throttle is the fraction of the control step at full thrust,
|a_cmd| / (F/m), at most 1), gated by the Schmitt trigger of :mod:`gnc_jax.guidance.trigger`
(the same one as the LOS and APN laws), a dead band that keeps navigation noise from firing
the engine: the gate opens when |a_cmd| >= a_on and closes when |a_cmd| <= a_off. No burn after
the guidance cut-off. With ``relaxed=True`` the trigger is its smooth relaxation
(temperature), for gradients with respect to N and the thresholds.
"""

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp

from ..._types import Scalar
from ...geometry.los import los_rate
from ...params import param
from ...schema import ScenarioError
from ..base import EngineCommand, register_law, safe_unit
from ..trigger import schmitt_trigger
from .base import AbstractImpactorGuidance


class PNState(NamedTuple):
    engine_on: Scalar  # 0/1 (hard) or in [0, 1] (relaxed)
    command_mps2: Scalar  # |a_cmd| at the last step (diagnostics)


@register_law("pn")
class ProportionalNavigationGuidance(AbstractImpactorGuidance):
    """PN on the filter's estimate, pulse-width modulated, gated by a Schmitt trigger (module
    docstring).
    ``n``, ``a_on_mps2``, ``a_off_mps2`` are differentiable leaves."""

    n: Scalar = param(3.0, lo=1.0, hi=20.0, doc="navigation constant N", tunable=True)
    a_on_mps2: Scalar = param(
        0.2,
        toml="trigger_on_mmps2",
        scale=1e-3,
        lo=0.0,
        lo_open=True,
        hi=1e4,
        units="mm/s^2",
        doc="the engine fires when |a_cmd| reaches it",
        tunable=True,
    )
    a_off_mps2: Scalar = param(
        0.1,
        toml="trigger_off_mmps2",
        scale=1e-3,
        lo=0.0,
        lo_open=True,
        hi=1e4,
        units="mm/s^2",
        doc="the engine stops when |a_cmd| falls to it; < trigger_on_mmps2",
        tunable=True,
    )
    temperature: Scalar = param(
        0.05, lo=0.0, lo_open=True, hi=10.0, doc="temperature of the relaxed trigger (gradients)"
    )
    relaxed: bool = eqx.field(static=True, default=False)

    ordered_gains = (("trigger_on_mmps2", "trigger_off_mmps2"),)

    @classmethod
    def check(cls, section, config):
        super().check(section, config)
        if section["trigger_off_mmps2"] >= section["trigger_on_mmps2"]:
            raise ScenarioError(
                f"guidance.pn.trigger_off_mmps2: {section['trigger_off_mmps2']:g} >= "
                f"trigger_on_mmps2 = {section['trigger_on_mmps2']:g}; allowed: 0 < off < on"
            )

    def init(self, nav, ctx) -> PNState:
        z = jnp.zeros(())
        return PNState(z, z)

    def step(self, state: PNState, nav, t, ctx):
        rho = ctx.aim_point(t) - nav.r
        rho_dot = -nav.v
        u = rho / jnp.linalg.norm(rho)
        closing = -jnp.dot(rho, rho_dot) / jnp.linalg.norm(rho)
        a_cmd = self.n * closing * jnp.cross(los_rate(rho, rho_dot), u)
        magnitude = jnp.linalg.norm(a_cmd)
        temperature = self.temperature if self.relaxed else None
        on = schmitt_trigger(
            magnitude, state.engine_on, self.a_on_mps2, self.a_off_mps2, temperature
        )
        on = jnp.where(t < ctx.cutoff_time_s, on, 0.0)
        full_thrust_mps2 = ctx.engine.thrust_n / ctx.mass_kg
        throttle = on * jnp.minimum(magnitude / full_thrust_mps2, 1.0)
        direction = safe_unit(a_cmd, ctx.c_bi[1])
        return EngineCommand(throttle, direction), PNState(on, magnitude)
