# ruff: noqa: F722  (jaxtyping shape strings such as "n" are not Python expressions)
"""Autonomous midcourse correction of an Earth–Mars transfer (seed 001 §3-4).

One dispersed run per call (`simulate`); Monte Carlo batches ``vmap`` it over per-run keys.
The run starts at the first navigation fix (the paper's E-238 d) on the nominal transfer plus
the initial (injection) error, then repeats the paper's cycle at every fix (seed 001 §3):

1. the navigation system gives the state with its error (bias + random, per fix);
2. the guidance law (a member of the midcourse family, `guidance.targeting`; the scenario's is
   `AutonomousCorrection`) is stepped on that state and the on-board predictor
   (`MidcourseSimulation.guidance_context`): it predicts Q = (B_R, B_T[, t]) by integrating the
   state to the Mars encounter and, unless the error is below the lower threshold (no burn) or
   above the upper one (flagged for the ground, no burn), commands the Δv found by Newton
   iteration;
3. the Δv is executed with magnitude and pointing errors, and the true state is propagated to
   the next fix.

After the last fix the true state is propagated to the encounter; the outcome is its B-plane and
arrival-time error with respect to the aim, the Δv per fix and in total, and a `Status`.
Epochs are seconds past J2000 TDB; the arrival-time target is relative to the nominal
encounter epoch. Everything is SI.
"""

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._numerics import safe_norm
from ..._random import normal, stream_key, stream_normal
from ..._status import Status
from ..._types import Array, Float, PRNGKeyArray, Scalar, State6, Vector3
from ...dynamics.heliocentric import HeliocentricModel, propagate
from ...guidance.midcourse import (
    AbstractMidcourseGuidance,
    AbstractSensitivity,
    MidcourseGuidanceContext,
    TargetingResult,
)
from ..loop import LoopState, closed_loop, with_status
from .params import MidcourseErrors


class MidcourseSimulation(eqx.Module):
    """Everything one run needs except the guidance law (an `AbstractMidcourseGuidance`) and
    the key.

    Attributes:
        model: heliocentric force model and integrator.
        r0_m, v0_mps: nominal heliocentric state at the first fix (EME2000).
        t_first_fix_s: epoch of the first fix; fix_interval_s: time between fixes.
        t_encounter_s: nominal periapsis epoch (the arrival-time target).
        t_max_s: end of the window in which the closest approach is searched.
        aim: Q_target = (B_R, B_T[, 0]) in m (and s, relative to t_encounter_s).
        ref_normal: B-plane reference-plane normal (EME2000).
        goal: (|ΔB| in m, |Δt| in s) success goal of the statistics (paper: 10 km, 60 s).
        errors: error sources.
        n_fixes: number of fixes (static); guidance_enabled: correct at all (static);
        reference_dv: also solve the error-free correction from the true initial state, the
            baseline of ``dv_increase_pct`` (static; needed only with navigation or execution
            errors, otherwise the first correction is that baseline).
    """

    model: HeliocentricModel
    r0_m: Vector3
    v0_mps: Vector3
    t_first_fix_s: Scalar
    fix_interval_s: Scalar
    t_encounter_s: Scalar
    t_max_s: Scalar
    aim: Float[Array, " n"]
    ref_normal: Vector3
    goal: Float[Array, "2"]
    errors: MidcourseErrors
    n_fixes: int = eqx.field(static=True, default=1)
    guidance_enabled: bool = eqx.field(static=True, default=True)
    reference_dv: bool = eqx.field(static=True, default=False)

    @property
    def fixed_arrival(self) -> bool:
        return self.aim.shape[0] == 3

    @property
    def guidance_context(self) -> MidcourseGuidanceContext:
        """The on-board predictor the guidance law works with (same model, aim and window)."""
        return MidcourseGuidanceContext(
            model=self.model,
            aim=self.aim,
            ref_normal=self.ref_normal,
            t_encounter_s=self.t_encounter_s,
            t_max_s=self.t_max_s,
        )


class MidcourseOutcome(NamedTuple):
    """Per-run results. ``b_err`` is B - aim in the B-plane (R, T components and magnitude);
    ``tof_err_s`` the arrival-time error (periapsis epoch minus the nominal); ``*0`` the same
    without any correction (the dispersion before correction)."""

    status: Array  # int, Status
    b_err_m: Scalar
    b_err_r_m: Scalar
    b_err_t_m: Scalar
    tof_err_s: Scalar
    b0_err_m: Scalar
    b0_err_r_m: Scalar
    b0_err_t_m: Scalar
    tof0_err_s: Scalar
    goal_met: Array  # bool: |ΔB| < goal and |Δt| < goal
    dv_mps: Scalar  # total executed Δv (sum of magnitudes)
    dv_first_mps: Scalar  # executed Δv of the first correction
    dv_ref_mps: Scalar  # error-free single correction from the true initial state
    dv_increase_pct: Scalar  # 100 (dv / dv_ref - 1)
    corrections: Array  # int, burns executed
    ground_calls: Array  # int, fixes flagged for the ground
    iterations: Array  # int, Newton updates of the first correction
    dv_per_fix_mps: Float[Array, " fixes"]  # executed Δv magnitude at each fix (0: no burn)
    predicted_b_err_m: Float[Array, " fixes"]  # on-board predicted |ΔB| at each fix
    initial_position_error_m: Vector3
    initial_velocity_error_mps: Vector3


class FixRecord(NamedTuple):
    """Per-fix trace of one run (``simulate(..., record=True)``)."""

    t_s: Scalar
    predicted_dq: Float[Array, " n"]  # on-board Q - Q_target before the decision
    dv_command_mps: Vector3
    dv_executed_mps: Vector3
    corrected: Array
    ground: Array
    converged: Array
    iterations: Array


# Stream identifiers for jax.random.fold_in (each kind of draw has its own stream).
_INITIAL_POSITION, _INITIAL_VELOCITY, _NAVIGATION, _EXECUTION = range(4)


def terminal_parameters(sim: MidcourseSimulation, t_s, state) -> Float[Array, "3"]:
    """(B_R, B_T, t_arrival - t_encounter) of a heliocentric state near the encounter
    (`MidcourseGuidanceContext.terminal_parameters`)."""
    return sim.guidance_context.terminal_parameters(t_s, state)


def predict(sim: MidcourseSimulation, t_s, state) -> tuple[Float[Array, "3"], Array]:
    """``(terminal parameters, status)`` of the trajectory through ``state`` at ``t_s``."""
    return sim.guidance_context.predict(t_s, state)


def sensitivity(sim: MidcourseSimulation, method: AbstractSensitivity, t_s, state):
    """``(Q, K = ∂Q/∂Δv)`` at ``state`` (epoch ``t_s``, zero Δv) by ``method``."""
    return method.q_and_jacobian(sim.guidance_context.problem(t_s, state), jnp.zeros(3))


def execute_burn(dv: Vector3, errors: MidcourseErrors, noise: Float[Array, "3"]) -> Vector3:
    """Executed Δv: magnitude (1 + bias + σ n0), direction tilted by σ_p (n1, n2) about two axes
    normal to the commanded direction. A zero command executes as zero (finite derivatives)."""
    magnitude = safe_norm(dv)
    burn = magnitude > 0.0
    u = jnp.where(burn, dv / jnp.where(burn, magnitude, 1.0), jnp.array([1.0, 0.0, 0.0]))
    helper = jnp.where(jnp.abs(u[2]) < 0.9, jnp.array([0.0, 0.0, 1.0]), jnp.array([1.0, 0.0, 0.0]))
    e1 = jnp.cross(u, helper)
    e1 = e1 / jnp.linalg.norm(e1)
    e2 = jnp.cross(u, e1)
    tilted = u + errors.pointing_sigma_rad * (noise[1] * e1 + noise[2] * e2)
    tilted = tilted / jnp.linalg.norm(tilted)
    scale = 1.0 + errors.magnitude_bias + errors.magnitude_sigma * noise[0]
    return magnitude * scale * tilted


def _solve_correction(sim, law, t_s, state) -> TargetingResult:
    """The law's Newton solution at ``state`` (``benchmarks/midcourse.py`` times it)."""
    return law.solve(sim.guidance_context.problem(t_s, state), sim.aim)


def initial_state(sim: MidcourseSimulation, key: PRNGKeyArray):
    """``(x0, dr, dv)``: the dispersed true state at the first fix and its position and velocity
    errors (offset + 1-sigma draw per axis)."""
    err = sim.errors
    dr = err.position_offset_m + err.position_m * stream_normal(key, _INITIAL_POSITION)
    dv = err.velocity_offset_mps + err.velocity_mps * stream_normal(key, _INITIAL_VELOCITY)
    return jnp.concatenate([sim.r0_m + dr, sim.v0_mps + dv]), dr, dv


def navigated_state(sim: MidcourseSimulation, key: PRNGKeyArray, i, x: State6) -> State6:
    """The navigation system's state at fix ``i``: the true ``x`` plus bias + random error,
    scaled by ``final_fix_scale`` at the last fix."""
    err = sim.errors
    scale = jnp.where(i == sim.n_fixes - 1, err.final_fix_scale, 1.0)
    noise = normal(stream_key(key, _NAVIGATION, i), (6,))
    nav_error = jnp.concatenate(
        [
            err.nav_position_bias_m + err.nav_position_m * noise[:3],
            err.nav_velocity_bias_mps + err.nav_velocity_mps * noise[3:],
        ]
    )
    return x + scale * nav_error


class FixTally(NamedTuple):
    """What the outcome counts over the fixes (the ``tally`` of the run's
    :class:`~gnc_jax.systems.loop.LoopState`)."""

    dv_mps: Scalar  # total executed Δv (sum of magnitudes)
    corrections: Array  # int, burns executed
    ground_calls: Array  # int, fixes flagged for the ground
    failed: Array  # a correction was needed but the targeter did not converge
    dv_first_mps: Scalar  # executed Δv of the first correction
    first_iterations: Array  # int, Newton updates of the first correction
    propagation_ok: Array  # every coast between fixes succeeded
    dv_per_fix_mps: Float[Array, " fixes"]  # executed Δv magnitude at each fix (0: no burn)
    predicted_b_err_m: Float[Array, " fixes"]  # on-board predicted |ΔB| at each fix


class Dispersion(NamedTuple):
    """What a run draws once and what follows from it alone: the dispersed true state at the
    first fix, its position and velocity errors, and the trajectory's terminal parameters and
    propagation status without any correction."""

    x0: State6
    position_error_m: Vector3
    velocity_error_mps: Vector3
    q0: Float[Array, "3"]
    status0: Array


def start(
    sim: MidcourseSimulation, law: AbstractMidcourseGuidance, key: PRNGKeyArray
) -> tuple[LoopState, Dispersion]:
    """The loop state at the first fix and the run's :class:`Dispersion`.

    The truth is the heliocentric state (a ``State6`` array); there is no carried estimate
    (the navigation state is a fresh draw around the truth at every fix) nor actuator memory
    (burns are impulsive), so both are ``()``; the law's state is ``None`` without guidance.
    """
    x0, dr, dv = initial_state(sim, key)
    q0, status0 = predict(sim, sim.t_first_fix_s, x0)
    law_state = None
    if sim.guidance_enabled:
        law_state = law.init(navigated_state(sim, key, 0, x0), sim.guidance_context)
    z, zi = jnp.zeros(()), jnp.zeros((), jnp.int32)
    tally = FixTally(
        dv_mps=z,
        corrections=zi,
        ground_calls=zi,
        failed=jnp.array(False),
        dv_first_mps=z,
        first_iterations=zi,
        propagation_ok=jnp.array(True),
        dv_per_fix_mps=jnp.zeros(sim.n_fixes),
        predicted_b_err_m=jnp.zeros(sim.n_fixes),
    )
    state = LoopState(truth=x0, estimate=(), law=law_state, actuator=(), tally=tally)
    return state, Dispersion(x0, dr, dv, q0, status0)


def _fix(
    sim: MidcourseSimulation,
    law: AbstractMidcourseGuidance,
    ctx: MidcourseGuidanceContext,
    key: PRNGKeyArray,
    record: bool,
    state: LoopState,
    i,
):
    """One navigation fix: navigate, let the law command, execute with errors, coast on."""
    t = sim.t_first_fix_s + i * sim.fix_interval_s
    nav = navigated_state(sim, key, i, state.truth)
    command, law_state = law.step(state.law, nav, t, ctx)
    noise = normal(stream_key(key, _EXECUTION, i), (3,))
    dv_exec = execute_burn(command.dv_mps, sim.errors, noise)
    dv_norm = safe_norm(dv_exec)
    tally = state.tally
    is_first = command.burn & (tally.corrections == 0)
    x = state.truth.at[3:].add(dv_exec)
    # Coast to the next fix (the last fix's state is the one propagated to encounter).
    t_next = jnp.where(i == sim.n_fixes - 1, t, t + sim.fix_interval_s)
    x, status = propagate(sim.model, t, x, t_next)
    dq = command.predicted_dq
    tally = FixTally(
        dv_mps=tally.dv_mps + dv_norm,
        corrections=tally.corrections + command.burn.astype(jnp.int32),
        ground_calls=tally.ground_calls + command.ground.astype(jnp.int32),
        failed=tally.failed | command.no_convergence,
        dv_first_mps=jnp.where(is_first, dv_norm, tally.dv_first_mps),
        first_iterations=jnp.where(is_first, command.iterations, tally.first_iterations),
        propagation_ok=tally.propagation_ok & (status == Status.ok),
        dv_per_fix_mps=tally.dv_per_fix_mps.at[i].set(dv_norm),
        predicted_b_err_m=tally.predicted_b_err_m.at[i].set(jnp.hypot(dq[0], dq[1])),
    )
    rec = None
    if record:
        rec = FixRecord(
            t_s=t,
            predicted_dq=dq,
            dv_command_mps=command.dv_mps,
            dv_executed_mps=dv_exec,
            corrected=command.burn,
            ground=command.ground,
            converged=command.converged,
            iterations=command.iterations,
        )
    return state._replace(truth=x, law=law_state, tally=tally), rec


def run(
    sim: MidcourseSimulation,
    law: AbstractMidcourseGuidance,
    key: PRNGKeyArray,
    dispersion: Dispersion,
    state: LoopState,
    record: bool,
) -> tuple[LoopState, FixRecord | None]:
    """The correction cycle over every fix; without guidance the flown trajectory is the
    initial one, and every fix predicts its miss."""
    if not sim.guidance_enabled:
        q0 = dispersion.q0
        b_pred = jnp.full(sim.n_fixes, jnp.hypot(q0[0] - sim.aim[0], q0[1] - sim.aim[1]))
        return state._replace(tally=state.tally._replace(predicted_b_err_m=b_pred)), None
    fix = functools.partial(_fix, sim, law, sim.guidance_context, key, record)
    return jax.lax.scan(fix, state, jnp.arange(sim.n_fixes))


def finish(
    sim: MidcourseSimulation,
    law: AbstractMidcourseGuidance,
    key: PRNGKeyArray,
    dispersion: Dispersion,
    state: LoopState,
) -> MidcourseOutcome:
    """The coast to the encounter and the run's outcome, its status ``nan`` (not finite, or a
    coast between fixes failed), else the worse propagation status to the encounter, else
    ``no_convergence``, else ``out_of_domain`` when a fix was handed to the ground (its error
    beyond the law's upper threshold: the autonomous correction did not deliver the run, and
    its miss, uncorrected at that fix, is left out of the statistics)."""
    tally, x0, q0, status0 = state.tally, dispersion.x0, dispersion.q0, dispersion.status0
    if sim.guidance_enabled:
        t0 = sim.t_first_fix_s
        t_last = t0 + (sim.n_fixes - 1) * sim.fix_interval_s
        q1, status1 = predict(sim, t_last, state.truth)
        if sim.reference_dv:
            # The error-free correction: the law's targeted Δv from the true initial state.
            ctx = sim.guidance_context
            command, _ = law.step(law.init(x0, ctx), x0, t0, ctx)
            dv_ref = safe_norm(command.dv_targeted_mps)
        else:
            dv_ref = tally.dv_first_mps
    else:
        q1, status1, dv_ref = q0, status0, jnp.zeros(())
    aim3 = jnp.concatenate([sim.aim, jnp.zeros(3 - sim.aim.shape[0])])
    d0, d1 = q0 - aim3, q1 - aim3
    b0, b1 = jnp.hypot(d0[0], d0[1]), jnp.hypot(d1[0], d1[1])
    safe_ref = jnp.where(dv_ref > 0.0, dv_ref, 1.0)
    outcome = MidcourseOutcome(
        status=jnp.zeros((), jnp.int32),
        b_err_m=b1,
        b_err_r_m=d1[0],
        b_err_t_m=d1[1],
        tof_err_s=d1[2],
        b0_err_m=b0,
        b0_err_r_m=d0[0],
        b0_err_t_m=d0[1],
        tof0_err_s=d0[2],
        goal_met=(b1 < sim.goal[0]) & (jnp.abs(d1[2]) < sim.goal[1]),
        dv_mps=tally.dv_mps,
        dv_first_mps=tally.dv_first_mps,
        dv_ref_mps=dv_ref,
        dv_increase_pct=jnp.where(dv_ref > 0.0, 100.0 * (tally.dv_mps / safe_ref - 1.0), 0.0),
        corrections=tally.corrections,
        ground_calls=tally.ground_calls,
        iterations=tally.first_iterations,
        dv_per_fix_mps=tally.dv_per_fix_mps,
        predicted_b_err_m=tally.predicted_b_err_m,
        initial_position_error_m=dispersion.position_error_m,
        initial_velocity_error_mps=dispersion.velocity_error_mps,
    )
    bad_status = jnp.maximum(status0, status1)
    failures = (
        (~tally.propagation_ok, Status.nan),
        (bad_status != Status.ok, bad_status),
        (tally.failed, Status.no_convergence),
        (tally.ground_calls > 0, Status.out_of_domain),
    )
    return with_status(outcome, failures)


def simulate(
    sim: MidcourseSimulation,
    law: AbstractMidcourseGuidance,
    key: PRNGKeyArray,
    record: bool = False,
) -> tuple[MidcourseOutcome, FixRecord | None]:
    """Simulate one dispersed transfer with the autonomous correction cycle.

    Args:
        sim: scenario data (see `MidcourseSimulation`).
        law: the midcourse guidance law (e.g. `AutonomousCorrection`), stepped at every fix.
        key: this run's key, ``jax.random.fold_in(root, run_index)``.
        record: also return the per-fix `FixRecord` trace (static).

    Returns:
        ``(outcome, trace)``; ``trace`` is ``None`` unless ``record``.
    """


# The signature and docstring above; the body is the shared skeleton of start, run, finish.
simulate = functools.wraps(simulate)(closed_loop(start, run, finish))


__all__ = [
    "Dispersion",
    "FixRecord",
    "FixTally",
    "MidcourseOutcome",
    "MidcourseSimulation",
    "execute_burn",
    "finish",
    "initial_state",
    "navigated_state",
    "predict",
    "run",
    "sensitivity",
    "simulate",
    "start",
    "terminal_parameters",
]
