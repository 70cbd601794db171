"""Predictive (Deep Impact style) terminal guidance (seed 000 baseline, seed 002 §3.3).

At each scheduled time the on-board predictor integrates the navigation state through the burn
to the B-plane; the predicted miss Δr_f = B_pred - aim is linearised, Δr_f = K Δv with K the
Jacobian of the predictor (computed by forward-mode autodiff), solved for the minimum-norm Δv
(2 equations, 3 unknowns: Δv = K^T (K K^T)^-1 Δr_f), applied and re-linearised — a fixed number
of Newton iterations, masked once the predicted miss is inside the tolerance. Burns are finite:
the predictor models the burn at the engine's thrust, and the law commands it as a timed burn
(open-loop duration, so the engine's execution error is not corrected by the law itself).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..._numerics import smooth_norm
from ..._types import Array, Float, Scalar, Vector3
from ...dynamics.impactor import ImpactorState, coast_to_b_plane, propagate
from ...params import from_config, param
from ...schema import ScenarioError
from ..base import EngineCommand, register_law, safe_unit
from .base import (
    AbstractImpactorGuidance,
    ImpactorGuidanceContext,
    mission_time_s,
    nominal_time_of_flight_s,
)


class PredictiveGuidanceState(NamedTuple):
    burn_start_s: Scalar
    burn_duration_s: Scalar
    burn_direction: Vector3
    burn_dv_mps: Scalar  # magnitude of the last commanded Δv
    mass_kg: Scalar  # on-board mass estimate (nominal flow)
    predicted_miss_m: Scalar  # |B_pred - aim| before the last burn
    burns: Scalar  # number of burns commanded so far
    residual_m: Scalar  # largest |B_pred - aim| left by a burn's Newton solve so far (inf for
    # a burn that does not end before the cut-off: the engine stops there)


def _time_of_flight_s(config) -> float:
    """The nominal time of flight (s) of a validated scenario, rounded as the simulation's."""
    a = config["approach"]
    return nominal_time_of_flight_s(a["position_km"], a["velocity_kmps"])


@register_law("predictive")
class PredictiveGuidance(AbstractImpactorGuidance):
    """Scheduled predictive guidance. ``burn_times_s``: mission times of the burns (seed 002:
    1200, 4100, 6450, 6780 s), at most one per image interval; or ``burn_tgo_s``: the same
    schedule as times to go before the nominal impact (seed 002: 6000, 3100, 750, 420 s), which
    scales with the approach's duration and, when given, replaces ``burn_times_s``."""

    burn_times_s: Float[Array, " n"] = param(
        [1200.0, 4100.0, 6450.0, 6780.0],
        lo=0.0,
        min_length=1,
        units="s",
        doc="mission times of the burns (ignored when burn_tgo_s is given)",
    )
    burn_tgo_s: Float[Array, " m"] = param(
        [],
        lo=0.0,
        units="s",
        doc="times to go before the nominal impact of the burns, decreasing (e.g. seed 002: "
        "[6000, 3100, 750, 420]); empty: burn_times_s is the schedule",
    )
    tolerance_m: Scalar = param(
        0.1,
        lo=0.0,
        lo_open=True,
        hi=1e6,
        units="m",
        doc="predicted-miss tolerance of the Newton iteration",
    )
    newton_iterations: int = param(4, lo=1, hi=50, doc="Newton iterations per burn")
    predictor_steps: int = param(4, lo=1, hi=10000, doc="RK4 steps per predictor segment")

    @staticmethod
    def schedule(section, config) -> tuple[list[float], str]:
        """The burns' mission times (s) of a validated scenario and the field that gave them:
        ``burn_tgo_s`` converted (t = time of flight - t_go, rounded to 1 us like every time
        derived from the time of flight) when given, else ``burn_times_s``."""
        tgo = section.get("burn_tgo_s") or []
        if tgo:
            tof = _time_of_flight_s(config)
            return [mission_time_s(tof, x) for x in tgo], "guidance.predictive.burn_tgo_s"
        return list(section["burn_times_s"]), "guidance.predictive.burn_times_s"

    @classmethod
    def check(cls, section, config):
        # The cut-off and retarget times as the simulation has them (rounded to 1 us): a burn
        # at "t_go = 750 s" on a 73440 km / 10.2 km/s approach is the burn at 6450 s.
        cam, g = config["camera"], config["guidance"]
        tof = _time_of_flight_s(config)
        t_cut = mission_time_s(tof, g["cutoff_tgo_s"])
        tgo = section.get("burn_tgo_s") or []
        outside = [x for x in tgo if not g["cutoff_tgo_s"] < x <= tof]
        if outside:
            raise ScenarioError(
                f"guidance.predictive.burn_tgo_s: a burn {outside[0]:g} s before impact is "
                f"outside the guided arc; allowed: times to go in ({g['cutoff_tgo_s']:g}, "
                f"{tof:g}] s (after guidance.cutoff_tgo_s, within the time of flight)"
            )
        if any(x2 >= x1 for x1, x2 in zip(tgo, tgo[1:])):
            raise ScenarioError(
                f"guidance.predictive.burn_tgo_s: {tgo} s; allowed: decreasing times to go"
            )
        bt, name = cls.schedule(section, config)
        if any(b2 <= b1 for b1, b2 in zip(bt, bt[1:])):
            raise ScenarioError(f"{name}: {bt} s; allowed: increasing mission times")
        late = [b for b in bt if b >= t_cut]
        if late:
            or_cutoff = f", or guidance.cutoff_tgo_s < {tof - max(bt):g} s" if tof > max(bt) else ""
            raise ScenarioError(
                f"{name}: the burn at {late[0]:g} s is not before the "
                f"cut-off at {t_cut:g} s (time of flight {tof:g} s - guidance.cutoff_tgo_s "
                f"{g['cutoff_tgo_s']:g} s); allowed: burns before {t_cut:g} s{or_cutoff}"
            )
        t_retarget = mission_time_s(tof, g["retarget_tgo_s"])
        if g["aim_final_km"] != g["aim_initial_km"] and not bt[-1] >= t_retarget:
            raise ScenarioError(
                f"guidance.retarget_tgo_s: the aim point changes at {t_retarget:g} s (time of "
                f"flight {tof:g} s - {g['retarget_tgo_s']:g} s), after the last burn of "
                f"{name} ({bt[-1]:g} s), so the new aim point is never "
                f"flown; allowed: a burn at or after {t_retarget:g} s (and before the cut-off at "
                f"{t_cut:g} s), or retarget_tgo_s >= {tof - bt[-1]:g} s"
            )
        for b1, b2 in zip(bt, bt[1:]):
            if b2 - b1 < cam["image_interval_s"]:
                gap = f"the burns at {b1:g} and {b2:g} s of {name}"
                raise ScenarioError(
                    f"camera.image_interval_s: {cam['image_interval_s']:g} s is longer than the "
                    f"{b2 - b1:g} s between {gap} (one image between burns); allowed: "
                    f"image_interval_s <= {b2 - b1:g} s, or burns increasing and at least one "
                    "image interval apart"
                )

    @classmethod
    def warnings(cls, section, config) -> list[str]:
        """A last burn in the first half of the guided arc: the rest of the approach is flown
        uncorrected, so the last burn's execution and navigation errors act over more than
        half the arc (seed 002 places it 420 s, 6 % of the arc, before impact). Allowed, but
        usually a schedule left over from another approach's timeline."""
        bt, name = cls.schedule(section, config)
        tof = _time_of_flight_s(config)
        arc = tof - config["guidance"]["cutoff_tgo_s"]
        if bt and bt[-1] < 0.5 * arc:
            return [
                f"{name}: the last burn is at {bt[-1]:g} s, {tof - bt[-1]:g} s before impact, in "
                f"the first half of the {arc:g} s guided arc; the rest is flown uncorrected "
                "(schedules that scale with the approach: guidance.predictive.burn_tgo_s)"
            ]
        return []

    @classmethod
    def from_config(cls, section, config, ctx=None):
        """The law with its schedule in mission times (``burn_tgo_s`` converted)."""
        bt, _ = cls.schedule(section, config)
        return from_config(cls, section, burn_times_s=jnp.asarray(bt, dtype=jnp.float64))

    def init(self, nav, ctx: ImpactorGuidanceContext) -> PredictiveGuidanceState:
        z = jnp.zeros(())
        return PredictiveGuidanceState(
            z - 1.0, z, ctx.c_bi[1], z, jnp.asarray(ctx.mass_kg, float), z, z, z
        )

    def predict_b_plane(self, nav, t, t_burn, dv, mass_kg, ctx) -> Float[Array, "2"]:
        """B-plane point after coasting from ``t`` to ``t_burn`` and a finite burn of ``dv``."""
        y = ImpactorState(nav.r, nav.v, mass_kg)
        y = propagate(ctx.dynamics, y, jnp.zeros(3), 0.0, t_burn - t, self.predictor_steps)
        thrust = ctx.engine.thrust_n
        dv_n = smooth_norm(dv)
        duration = dv_n * mass_kg / thrust
        y = propagate(
            ctx.dynamics,
            y,
            thrust * dv / dv_n,
            ctx.engine.mass_flow(1.0),
            duration,
            self.predictor_steps,
        )
        b, _ = coast_to_b_plane(ctx.dynamics, y, ctx.c_bi, self.predictor_steps)
        return b

    def solve_burn(self, nav, t, t_burn, mass_kg, ctx) -> tuple[Vector3, Scalar, Scalar]:
        """Newton iteration for the finite-burn Δv (m/s) that nulls the predicted miss:
        ``(dv, miss before, miss left)``, the predicted misses (m) at the straight-line first
        guess and at the solution (one prediction more, as the midcourse targeter's)."""
        aim = ctx.aim_b_plane(t_burn)
        tr = ctx.c_bi[1:]
        # Impulsive straight-line first guess: dB = t_go * dv_(T,R).
        y_burn = ImpactorState(nav.r + nav.v * (t_burn - t), nav.v, mass_kg)
        b0, t_go = coast_to_b_plane(ctx.dynamics, y_burn, ctx.c_bi, self.predictor_steps)
        dv0 = -((b0 - aim) / t_go) @ tr
        miss0 = jnp.linalg.norm(b0 - aim)

        def predicted(dv):
            return self.predict_b_plane(nav, t, t_burn, dv, mass_kg, ctx)

        def newton(_, dv):
            err = predicted(dv) - aim
            k = jax.jacfwd(predicted)(dv)
            step = k.T @ jnp.linalg.solve(k @ k.T, err)
            return jnp.where(jnp.linalg.norm(err) > self.tolerance_m, dv - step, dv)

        dv = jax.lax.fori_loop(0, self.newton_iterations, newton, dv0)
        return dv, miss0, jnp.linalg.norm(predicted(dv) - aim)

    def plan(self, state, nav, t, ctx: ImpactorGuidanceContext) -> PredictiveGuidanceState:
        window = (self.burn_times_s >= t) & (self.burn_times_s < t + ctx.image_interval_s)
        t_burn = jnp.sum(jnp.where(window, self.burn_times_s, 0.0))

        def schedule_burn(state):
            dv, miss0, left = self.solve_burn(nav, t, t_burn, state.mass_kg, ctx)
            dv_n = jnp.linalg.norm(dv)
            duration = dv_n * state.mass_kg / ctx.engine.thrust_n
            # A solution that does not end before the cut-off cannot be flown (a weak engine's
            # burn can even outlast the approach): its residual is not what is flown.
            left = jnp.where(t_burn + duration > ctx.cutoff_time_s, jnp.inf, left)
            return PredictiveGuidanceState(
                burn_start_s=t_burn,
                burn_duration_s=duration,
                burn_direction=safe_unit(dv, ctx.c_bi[1]),
                burn_dv_mps=dv_n,
                mass_kg=state.mass_kg,
                predicted_miss_m=miss0,
                burns=state.burns + 1.0,
                residual_m=jnp.maximum(state.residual_m, left),
            )

        # `t` and the schedule are shared by every run of a batch, so under vmap the predicate
        # stays unbatched and the predictor runs only in the image intervals that hold a burn.
        return jax.lax.cond(jnp.any(window), schedule_burn, lambda s: s, state)

    def converged(self, state):
        """Every burn's Newton solve ended within ``tolerance_m`` of the aim point (in the
        predictor's model; NaN reads as not converged) with a burn that ends before the
        cut-off."""
        return state.residual_m <= self.tolerance_m

    def step(self, state, nav, t, ctx: ImpactorGuidanceContext):
        end = state.burn_start_s + state.burn_duration_s
        overlap = jnp.minimum(t + ctx.dt_s, end) - jnp.maximum(t, state.burn_start_s)
        throttle = jnp.clip(overlap / ctx.dt_s, 0.0, 1.0)
        mass = state.mass_kg - ctx.engine.mass_flow(throttle) * ctx.dt_s
        return EngineCommand(throttle, state.burn_direction), state._replace(mass_kg=mass)
