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
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..._numerics import safe_norm
from ..._random import stream_normal
from ..._status import Status
from ..._types import Array, Float, PRNGKeyArray, Scalar, State6, Vector3
from ...constants import SECONDS_PER_DAY
from ...dynamics.ephemeris import (
    ECLIPTIC_POLE_EQUATORIAL,
    GM_PLANETS,
    GM_SUN,
    planet_index,
    planet_state,
)
from ...dynamics.heliocentric import (
    SOLAR_PRESSURE_1AU,
    EphemerisTable,
    HeliocentricModel,
    propagate,
    propagate_with_stm,
)
from ...geometry.bplane import BPlaneError, check_b_plane_frame
from ...geometry.kepler import propagate_kepler
from ...geometry.lambert import solve_lambert
from ...guidance.midcourse import (
    SENSITIVITY_METHODS,
    AbstractMidcourseGuidance,
    AbstractSensitivity,
    MidcourseGuidanceContext,
    NewtonTargeter,
    TargetingResult,
    jacobian_autodiff,
    jacobian_central_difference,
)
from ...schema import ScenarioError
from ..loop import with_status
from .params import MidcourseErrors, MidcourseParameters, parameters


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
    return law.targeter.solve(sim.guidance_context.problem(t_s, state), sim.aim, jnp.zeros(3))


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
    k_nav = jax.random.fold_in(jax.random.fold_in(key, _NAVIGATION), i)
    noise = jax.random.normal(k_nav, (6,))
    nav_error = jnp.concatenate(
        [
            err.nav_position_bias_m + err.nav_position_m * noise[:3],
            err.nav_velocity_bias_mps + err.nav_velocity_mps * noise[3:],
        ]
    )
    return x + scale * nav_error


class _Cycle(NamedTuple):
    """Carry of the scan over the fixes."""

    x: State6  # true state
    law_state: Any
    dv_total: Scalar
    corrections: Array
    ground_calls: Array
    failed: Array  # a correction was needed but the targeter did not converge
    first_dv: Scalar
    first_iterations: Array
    propagation_ok: Array


def _fix(
    sim: MidcourseSimulation,
    law: AbstractMidcourseGuidance,
    ctx: MidcourseGuidanceContext,
    key: PRNGKeyArray,
    cycle: _Cycle,
    i,
):
    """One navigation fix: navigate, let the law command, execute with errors, coast on."""
    t = sim.t_first_fix_s + i * sim.fix_interval_s
    nav = navigated_state(sim, key, i, cycle.x)
    command, law_state = law.step(cycle.law_state, nav, t, ctx)
    k_exec = jax.random.fold_in(jax.random.fold_in(key, _EXECUTION), i)
    dv_exec = execute_burn(command.dv_mps, sim.errors, jax.random.normal(k_exec, (3,)))
    dv_norm = safe_norm(dv_exec)
    is_first = command.burn & (cycle.corrections == 0)
    x = cycle.x.at[3:].add(dv_exec)
    # Coast to the next fix (the last fix's state is the one propagated to encounter).
    t_next = jnp.where(i == sim.n_fixes - 1, t, t + sim.fix_interval_s)
    x, status = propagate(sim.model, t, x, t_next)
    cycle = _Cycle(
        x,
        law_state,
        cycle.dv_total + dv_norm,
        cycle.corrections + command.burn.astype(jnp.int32),
        cycle.ground_calls + command.ground.astype(jnp.int32),
        cycle.failed | command.no_convergence,
        jnp.where(is_first, dv_norm, cycle.first_dv),
        jnp.where(is_first, command.iterations, cycle.first_iterations),
        cycle.propagation_ok & (status == Status.ok),
    )
    dq = command.predicted_dq
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
    return cycle, (dv_norm, jnp.hypot(dq[0], dq[1]), rec)


class _Flight(NamedTuple):
    """The flown transfer: the cycle's totals, the encounter and the per-fix series."""

    cycle: _Cycle
    q: Float[Array, "3"]  # terminal parameters of the flown trajectory
    status: Array  # its propagation status
    dv_ref: Scalar
    dv_per_fix: Float[Array, " fixes"]
    b_pred: Float[Array, " fixes"]
    record: Any


def _fly_corrected(
    sim: MidcourseSimulation, law: AbstractMidcourseGuidance, key: PRNGKeyArray, x0: State6
) -> _Flight:
    """The correction cycle over every fix, then the coast to the encounter."""
    ctx = sim.guidance_context
    t0 = sim.t_first_fix_s
    z, zi = jnp.zeros(()), jnp.zeros((), jnp.int32)
    law_state = law.init(navigated_state(sim, key, 0, x0), ctx)
    cycle0 = _Cycle(x0, law_state, z, zi, zi, jnp.array(False), z, zi, jnp.array(True))
    fix = functools.partial(_fix, sim, law, ctx, key)
    cycle, (dv_per_fix, b_pred, rec) = jax.lax.scan(fix, cycle0, jnp.arange(sim.n_fixes))
    t_last = t0 + (sim.n_fixes - 1) * sim.fix_interval_s
    q1, status1 = predict(sim, t_last, cycle.x)
    if sim.reference_dv:
        # The error-free correction: the law's targeted Δv from the true initial state.
        command, _ = law.step(law.init(x0, ctx), x0, t0, ctx)
        dv_ref = safe_norm(command.dv_targeted_mps)
    else:
        dv_ref = cycle.first_dv
    return _Flight(cycle, q1, status1, dv_ref, dv_per_fix, b_pred, rec)


def _fly_uncorrected(sim: MidcourseSimulation, x0: State6, q0, status0) -> _Flight:
    """No guidance: the flown trajectory is the initial one."""
    z, zi = jnp.zeros(()), jnp.zeros((), jnp.int32)
    cycle = _Cycle(x0, None, z, zi, zi, jnp.array(False), z, zi, jnp.array(True))
    b_pred = jnp.full(sim.n_fixes, jnp.hypot(q0[0] - sim.aim[0], q0[1] - sim.aim[1]))
    return _Flight(cycle, q0, status0, z, jnp.zeros(sim.n_fixes), b_pred, None)


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
    x0, dr, dv = initial_state(sim, key)
    q0, status0 = predict(sim, sim.t_first_fix_s, x0)
    if sim.guidance_enabled:
        flight = _fly_corrected(sim, law, key, x0)
    else:
        flight = _fly_uncorrected(sim, x0, q0, status0)
    outcome = _outcome(sim, q0, status0, flight, dr, dv)
    return outcome, (flight.record if record else None)


def _outcome(sim: MidcourseSimulation, q0, status0, flight: _Flight, dr, dv) -> MidcourseOutcome:
    """The run's outcome and its status: ``nan`` (not finite, or a coast between fixes
    failed), else the worse propagation status to the encounter, else ``no_convergence``."""
    cycle, dv_ref = flight.cycle, flight.dv_ref
    aim3 = jnp.concatenate([sim.aim, jnp.zeros(3 - sim.aim.shape[0])])
    d0, d1 = q0 - aim3, flight.q - aim3
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
        dv_mps=cycle.dv_total,
        dv_first_mps=cycle.first_dv,
        dv_ref_mps=dv_ref,
        dv_increase_pct=jnp.where(dv_ref > 0.0, 100.0 * (cycle.dv_total / safe_ref - 1.0), 0.0),
        corrections=cycle.corrections,
        ground_calls=cycle.ground_calls,
        iterations=cycle.first_iterations,
        dv_per_fix_mps=flight.dv_per_fix,
        predicted_b_err_m=flight.b_pred,
        initial_position_error_m=dr,
        initial_velocity_error_mps=dv,
    )
    bad_status = jnp.maximum(status0, flight.status)
    failures = (
        (~cycle.propagation_ok, Status.nan),
        (bad_status != Status.ok, bad_status),
        (cycle.failed, Status.no_convergence),
    )
    return with_status(outcome, failures)


class NominalTransfer(NamedTuple):
    """The nominal transfer a scenario defines (see `design_nominal`)."""

    r0_m: Vector3  # heliocentric state at the first fix, EME2000
    v0_mps: Vector3
    v_lambert_mps: Vector3  # the Sun-only Lambert conic's velocity at the first fix
    c3_km2s2: float  # launch energy of the Lambert conic
    v_inf_arrival_mps: float  # arrival excess speed of the Lambert conic
    design_iterations: int


@eqx.filter_jit
def _retarget(sim: MidcourseSimulation, targeter: NewtonTargeter):
    x = jnp.concatenate([sim.r0_m, sim.v0_mps])
    return targeter.solve(sim.guidance_context.problem(sim.t_first_fix_s, x), sim.aim, jnp.zeros(3))


_NOMINAL_CACHE: dict = {}


def design_nominal(sim: MidcourseSimulation, t_launch_s: float) -> NominalTransfer:
    """Nominal state at the first fix: Lambert conic, then full-model targeting.

    1. Zero-revolution Lambert arc (Sun only, Izzo) from the Earth–Moon barycentre at
       ``t_launch_s`` to Mars at the nominal encounter epoch (`geometry.lambert`);
    2. that conic propagated (Kepler) to the first-fix epoch;
    3. the velocity there retargeted by Newton iteration (autodiff K, 12 iterations) in the full
       model to the aim point and the encounter epoch, |ΔB| < 1 m, |Δt| < 1 ms.

    ``sim`` supplies the model, epochs and aim (its r0/v0 are ignored). Results are cached per
    process, keyed by every input. Raises `BPlaneError` when the arrival asymptote is parallel
    to the reference normal and ``ValueError`` when step 3 does not converge.
    """
    # Only the model, epochs, aim and reference plane matter; everything else is reset so that
    # every scenario variant shares one compiled design function and one cached result.
    aim3 = jnp.concatenate([sim.aim[:2], jnp.zeros(1)])
    design = MidcourseSimulation(
        model=sim.model,
        r0_m=jnp.zeros(3),
        v0_mps=jnp.zeros(3),
        t_first_fix_s=sim.t_first_fix_s,
        fix_interval_s=jnp.asarray(SECONDS_PER_DAY),
        t_encounter_s=sim.t_encounter_s,
        t_max_s=sim.t_max_s,
        aim=aim3,
        ref_normal=sim.ref_normal,
        goal=jnp.zeros(2),
        errors=MidcourseErrors(),
    )
    leaves = [jnp.asarray(x).tolist() for x in jax.tree_util.tree_leaves(design)]
    key = (repr(leaves), repr(jax.tree_util.tree_structure(design)), float(t_launch_s))
    if key in _NOMINAL_CACHE:
        return _NOMINAL_CACHE[key]
    t_enc = float(sim.t_encounter_s)
    t_fix = float(sim.t_first_fix_s)
    r_earth, v_earth = planet_state(planet_index("earth"), t_launch_s)
    r_mars, v_mars = planet_state(sim.model.target, t_enc)
    v1, v2 = solve_lambert(r_earth, r_mars, t_enc - t_launch_s, GM_SUN)
    check_b_plane_frame(v2 - v_mars, sim.ref_normal)
    r0, v0 = propagate_kepler(r_earth, v1, t_fix - t_launch_s, GM_SUN)
    design = eqx.tree_at(lambda s: (s.r0_m, s.v0_mps), design, (r0, v0))
    targeter = NewtonTargeter(tolerance=jnp.array([1.0, 1.0, 1e-3]), iterations=12)
    result = _retarget(design, targeter)
    if not bool(result.converged):
        miss = jax.device_get(result.q - aim3)
        raise ValueError(
            "the nominal transfer could not be targeted to the aim point in the full model "
            f"(residual B_R, B_T, t = {miss[0]:.3g} m, {miss[1]:.3g} m, {miss[2]:.3g} s)"
        )
    nominal = NominalTransfer(
        r0_m=r0,
        v0_mps=v0 + result.p,
        v_lambert_mps=v0,
        c3_km2s2=float(jnp.sum((v1 - v_earth) ** 2)) / 1e6,
        v_inf_arrival_mps=float(jnp.linalg.norm(v2 - v_mars)),
        design_iterations=int(result.iterations),
    )
    if len(_NOMINAL_CACHE) >= 16:
        _NOMINAL_CACHE.pop(next(iter(_NOMINAL_CACHE)))
    _NOMINAL_CACHE[key] = nominal
    return nominal


def reference_normal(plane: str, t_encounter_s: float) -> Vector3:
    """Normal of the B-plane reference plane in EME2000 (the ecliptic pole)."""
    if plane == "ecliptic":
        return jnp.asarray(ECLIPTIC_POLE_EQUATORIAL)
    if plane == "equator":
        return jnp.array([0.0, 0.0, 1.0])
    r, v = planet_state(planet_index("mars"), t_encounter_s)
    h = jnp.cross(r, v)
    return h / jnp.linalg.norm(h)


def _model(p: MidcourseParameters, t_max_s: float) -> HeliocentricModel:
    """The heliocentric force model of a scenario's parameters (SI)."""
    sc, dy = p.spacecraft, p.dynamics
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    srp = sc.reflectivity * sc.srp_area_m2 / sc.mass_kg if bool(dy.srp) else 0.0
    table = None
    if dy.ephemeris == "table":
        table = EphemerisTable.spanning(p.mission.first_fix_epoch_s, t_max_s)
    return HeliocentricModel(
        ephemeris=table,
        gm_planets=f(GM_PLANETS if bool(dy.planets) else [0.0] * 8),
        srp_m2_per_kg=f(srp),
        solar_pressure_npm2=f(SOLAR_PRESSURE_1AU),
        rtol=dy.rtol,
        atol=dy.atol,
        solver=dy.solver,
        max_steps=dy.max_steps,
    )


def _simulation(p: MidcourseParameters) -> MidcourseSimulation:
    """The simulation data of a scenario's parameters, before the nominal is designed."""
    mi, dy, nv, g = p.mission, p.dynamics, p.navigation, p.guidance
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    t_max = mi.encounter_epoch_s + dy.window_s
    aim = jnp.stack([mi.aim_b_m[1], mi.aim_b_m[0]])  # Q order: (B_R, B_T[, t])
    if g.targets == "b_plane_tof":
        aim = jnp.concatenate([aim, jnp.zeros(1)])
    enabled = bool(g.enabled)
    return MidcourseSimulation(
        model=_model(p, t_max),
        r0_m=jnp.zeros(3),
        v0_mps=jnp.zeros(3),
        t_first_fix_s=f(mi.first_fix_epoch_s),
        fix_interval_s=nv.fix_interval_s,
        t_encounter_s=f(mi.encounter_epoch_s),
        t_max_s=f(t_max),
        aim=aim,
        ref_normal=reference_normal(mi.reference_plane, mi.encounter_epoch_s),
        goal=jnp.stack([p.goal.b_m, p.goal.tof_s]),
        errors=p.errors,
        n_fixes=nv.fixes,
        guidance_enabled=enabled,
        reference_dv=enabled and p.errors.has_per_fix_errors(),
    )


def build(scenario) -> MidcourseSimulation:
    """Simulation data of a validated midcourse :class:`Scenario` (SI, from
    :func:`gnc_jax.systems.midcourse.params.parameters`); the law is built by the system from
    ``[guidance.<law>]`` (``systems.midcourse``).

    Designs the nominal transfer (`design_nominal`, cached) before returning; a nominal that
    cannot be targeted raises :class:`ScenarioError`.
    """
    p = parameters(scenario.config)
    sim = _simulation(p)
    try:
        nominal = design_nominal(sim, p.mission.launch_epoch_s)
    except BPlaneError as error:
        raise ScenarioError(
            f"mission.reference_plane: {p.mission.reference_plane!r}: {error}"
        ) from None
    except ValueError as error:
        raise ScenarioError(
            f"mission: {error}; allowed: epochs and aim point of a feasible transfer"
        ) from None
    return eqx.tree_at(lambda s: (s.r0_m, s.v0_mps), sim, (nominal.r0_m, nominal.v0_mps))


def _full_targets(sim: MidcourseSimulation) -> MidcourseSimulation:
    """The same simulation targeting all three parameters (B_R, B_T, t)."""
    aim3 = jnp.concatenate([sim.aim[:2], jnp.zeros(1)])
    return eqx.tree_at(lambda s: s.aim, sim, aim3)


@eqx.filter_jit
def partials_vs_step(sim: MidcourseSimulation, epsilons: Float[Array, " e"]):
    """Seed 001 Fig. 1: central-difference K against the step ε, and the autodiff K.

    At the nominal state at the first fix, for Q = (B_R, B_T, t). Returns
    ``(k_central_difference [e, 3, 3], k_autodiff [3, 3])``.
    """
    sim = _full_targets(sim)
    x = jnp.concatenate([sim.r0_m, sim.v0_mps])
    q = sim.guidance_context.problem(sim.t_first_fix_s, x).q
    k_cd = jax.vmap(lambda e: jacobian_central_difference(q, jnp.zeros(3), e)[1])(epsilons)
    return k_cd, jacobian_autodiff(q, jnp.zeros(3))[1]


def q_and_stm_jacobian_fixed_epoch(sim: MidcourseSimulation, t_s, state, t_end_s):
    """(Q, K) of the paper's STM formulation taken literally: the state and Φ are integrated to
    a fixed end epoch ``t_end_s`` and Q is the two-body (B-plane, Kepler t_TOF) prediction from
    the osculating planet-relative hyperbola there (seed 001 eqs. 22-34), not at the periapsis.

    For report figures only: the osculating conic away from periapsis is not the one flown (the
    solar tide bends the approach), and as the correction epoch nears ``t_end_s``, Φ -> I and
    K -> ∂Q/∂v(t_end), which is not zero: the paper's Fig. 3 behaviour.
    """

    def q_and_k(dv):
        x, phi_v, _ = propagate_with_stm(sim.model, t_s, state.at[3:].add(dv), t_end_s)
        q_of_x = lambda y: terminal_parameters(sim, t_end_s, y)[: sim.aim.shape[0]]
        return q_of_x(x), jax.jacfwd(q_of_x)(x) @ phi_v

    return q_and_k


@eqx.filter_jit
def partials_vs_time(sim: MidcourseSimulation, epochs_s: Float[Array, " k"], epsilon, t_end_s):
    """Seed 001 Figs. 2-3: K along the nominal trajectory at each epoch, by every method.

    Returns a dict ``{method: K [k, 3, 3]}``, Q = (B_R, B_T, t), for ``autodiff``,
    ``central_difference`` (step ``epsilon``), ``stm`` (to the periapsis epoch, as in the
    targeter) and ``stm_fixed_epoch`` (the paper's formulation with the fixed end epoch
    ``t_end_s``, `q_and_stm_jacobian_fixed_epoch`).
    """
    sim = _full_targets(sim)
    x0 = jnp.concatenate([sim.r0_m, sim.v0_mps])

    methods = {
        name: cls.from_config({"epsilon_mps": epsilon}) for name, cls in SENSITIVITY_METHODS.items()
    }

    def at(t):
        x, _ = propagate(sim.model, sim.t_first_fix_s, x0, t)
        out = {name: sensitivity(sim, method, t, x)[1] for name, method in methods.items()}
        fixed = q_and_stm_jacobian_fixed_epoch(sim, t, x, t_end_s)
        out["stm_fixed_epoch"] = fixed(jnp.zeros(3))[1]
        return out

    return jax.vmap(at)(epochs_s)
