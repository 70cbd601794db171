# ruff: noqa: F722  (jaxtyping shape strings such as "n" are not Python expressions)
"""Autonomous midcourse correction of an Earth–Mars transfer (seed 001 §3-4; SPEC §7).

One dispersed run per call (`simulate`); Monte Carlo batches ``vmap`` it over per-run keys.
The run starts at the first navigation fix (the paper's E-238 d) on the nominal transfer plus
the initial (injection) error, then repeats the paper's cycle at every fix (seed 001 §3):

1. the navigation system gives the state with its error (bias + random, per fix);
2. the targeter predicts Q = (B_R, B_T[, t]) by integrating that state to the Mars encounter
   and, unless the error is below the lower threshold (no burn) or above the upper one (flagged
   for the ground, no burn), computes the Δv by Newton iteration (`guidance.targeting`);
3. the Δv is executed with magnitude and pointing errors, and the true state is propagated to
   the next fix.

After the last fix the true state is propagated to the encounter; the outcome is its B-plane and
arrival-time error with respect to the aim, the Δv per fix and in total, and a `Status`.
Epochs are seconds past J2000 TDB; the arrival-time target is relative to the nominal
encounter epoch. Everything is SI.
"""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .._status import Status, all_finite
from .._types import Array, Float, PRNGKeyArray, Scalar, Vector3
from ..dynamics.heliocentric import (
    EphemerisTable,
    HeliocentricModel,
    propagate,
    propagate_to_encounter,
    propagate_to_encounter_with_stm,
    propagate_with_stm,
    relative_state,
)
from ..geometry.hyperbola import b_plane_hyperbolic
from ..guidance.targeting import (
    AutonomousCorrection,
    NewtonTargeter,
    jacobian_autodiff,
    jacobian_central_difference,
)


class MidcourseErrors(eqx.Module):
    """Error sources (SI, EME2000 axes). Initial errors are drawn once per run; navigation and
    execution errors at every fix.

    Attributes:
        position_m, velocity_mps: 1-sigma initial dispersion per axis (paper: 289 km, 0.577 m/s).
        position_offset_m, velocity_offset_mps: deterministic initial error (paper's cycle
            cases: 500 km and 1 m/s along x).
        nav_position_m, nav_velocity_mps: 1-sigma random navigation error per axis and fix.
        nav_position_bias_m, nav_velocity_bias_mps: constant navigation error (paper: 0.3 m/s x).
        final_fix_scale: factor on the last fix's navigation error (paper: 0.01 / 0.3).
        magnitude_bias, magnitude_sigma: burn magnitude error, systematic and 1-sigma (fraction).
        pointing_sigma_rad: 1-sigma burn pointing error about each axis normal to the burn.
    """

    position_m: Scalar = 289e3
    velocity_mps: Scalar = 0.577
    position_offset_m: Vector3 = eqx.field(default_factory=lambda: jnp.zeros(3))
    velocity_offset_mps: Vector3 = eqx.field(default_factory=lambda: jnp.zeros(3))
    nav_position_m: Scalar = 0.0
    nav_velocity_mps: Scalar = 0.0
    nav_position_bias_m: Vector3 = eqx.field(default_factory=lambda: jnp.zeros(3))
    nav_velocity_bias_mps: Vector3 = eqx.field(default_factory=lambda: jnp.zeros(3))
    final_fix_scale: Scalar = 1.0
    magnitude_bias: Scalar = 0.0
    magnitude_sigma: Scalar = 0.0
    pointing_sigma_rad: Scalar = 0.0


class MidcourseSimulation(eqx.Module):
    """Everything one run needs except the guidance (`AutonomousCorrection`) and the key.

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


def _normal(key, stream, shape=(3,)):
    return jax.random.normal(jax.random.fold_in(key, stream), shape)


def terminal_parameters(sim: MidcourseSimulation, t_s, state) -> Float[Array, "3"]:
    """(B_R, B_T, t_arrival - t_encounter) of a heliocentric state near the encounter.

    The arrival time is the epoch plus the linearised time of flight to periapsis (seed 001
    eqs. 27-32); all components are planet-relative two-body constants (`geometry.hyperbola`).
    The targeted Q is the first n = ``sim.aim.shape[0]`` components.
    """
    r_rel, v_rel = relative_state(sim.model, t_s, state)
    bp = b_plane_hyperbolic(r_rel, v_rel, sim.model.gm_target, sim.ref_normal)
    return jnp.stack([bp.b_r, bp.b_t, (t_s - sim.t_encounter_s) + bp.t_tof])


def predict(sim: MidcourseSimulation, t_s, state) -> tuple[Float[Array, "3"], Array]:
    """``(terminal parameters, status)`` of the trajectory through ``state`` at ``t_s``."""
    enc = propagate_to_encounter(sim.model, t_s, state, sim.t_max_s)
    return terminal_parameters(sim, enc.t_s, enc.state), enc.status


def q_function(sim: MidcourseSimulation, t_s, state):
    """P = Δv (m/s, EME2000) applied at ``t_s`` -> Q: the on-board predictor of the targeter."""
    n = sim.aim.shape[0]
    return lambda dv: predict(sim, t_s, state.at[3:].add(dv))[0][:n]


def q_and_stm_jacobian(sim: MidcourseSimulation, t_s, state):
    """Δv -> (Q, K) with K = ∂Q/∂X_f Φ(t_f, t) ∂X/∂Δv (seed 001 eq. 22) from the variational
    equations; ∂Q/∂X_f is the derivative of the closed-form B-plane formulas at fixed t_f."""

    def q_and_k(dv):
        enc, phi_v = propagate_to_encounter_with_stm(
            sim.model, t_s, state.at[3:].add(dv), sim.t_max_s
        )
        q_of_x = lambda x: terminal_parameters(sim, enc.t_s, x)[: sim.aim.shape[0]]
        return q_of_x(enc.state), jax.jacfwd(q_of_x)(enc.state) @ phi_v

    return q_and_k


def sensitivity(sim: MidcourseSimulation, method: str, t_s, state, epsilon=1e-3):
    """``(Q, K = ∂Q/∂Δv)`` at ``state`` (epoch ``t_s``) by ``method`` (`SENSITIVITIES`)."""
    dv0 = jnp.zeros(3)
    if method == "autodiff":
        return jacobian_autodiff(q_function(sim, t_s, state), dv0)
    if method == "central_difference":
        return jacobian_central_difference(q_function(sim, t_s, state), dv0, epsilon)
    return q_and_stm_jacobian(sim, t_s, state)(dv0)


def _safe_norm(x):
    """|x| with a zero (not NaN) derivative at x = 0."""
    n2 = x @ x
    ok = n2 > 0.0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, n2, 1.0)), 0.0)


def execute_burn(dv: Vector3, errors: MidcourseErrors, noise: Float[Array, "3"]) -> Vector3:
    """Executed Δv: magnitude (1 + bias + σ n0), direction tilted by σ_p (n1, n2) about two axes
    normal to the commanded direction. A zero command executes as zero (finite derivatives)."""
    magnitude = _safe_norm(dv)
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


def _solve_correction(sim, law: AutonomousCorrection, t_s, state):
    stm = q_and_stm_jacobian(sim, t_s, state) if law.targeter.sensitivity == "stm" else None
    return law.targeter.solve(q_function(sim, t_s, state), sim.aim, jnp.zeros(3), stm)


def simulate(
    sim: MidcourseSimulation,
    law: AutonomousCorrection,
    key: PRNGKeyArray,
    record: bool = False,
) -> tuple[MidcourseOutcome, FixRecord | None]:
    """Simulate one dispersed transfer with the autonomous correction cycle.

    Args:
        sim: scenario data (see `MidcourseSimulation`).
        law: the correction rule and its targeter (`AutonomousCorrection`).
        key: this run's key, ``jax.random.fold_in(root, run_index)``.
        record: also return the per-fix `FixRecord` trace (static).

    Returns:
        ``(outcome, trace)``; ``trace`` is ``None`` unless ``record``.
    """
    err = sim.errors
    dr = err.position_offset_m + err.position_m * _normal(key, _INITIAL_POSITION)
    dv = err.velocity_offset_mps + err.velocity_mps * _normal(key, _INITIAL_VELOCITY)
    x0 = jnp.concatenate([sim.r0_m + dr, sim.v0_mps + dv])
    t0 = sim.t_first_fix_s
    q0, status0 = predict(sim, t0, x0)

    def fix(carry, i):
        x, dv_total, count, ground_count, failed, first_dv, first_iter, prop_ok = carry
        t = t0 + i * sim.fix_interval_s
        scale = jnp.where(i == sim.n_fixes - 1, err.final_fix_scale, 1.0)
        k_nav = jax.random.fold_in(jax.random.fold_in(key, _NAVIGATION), i)
        noise = jax.random.normal(k_nav, (6,))
        nav_error = jnp.concatenate(
            [
                err.nav_position_bias_m + err.nav_position_m * noise[:3],
                err.nav_velocity_bias_mps + err.nav_velocity_mps * noise[3:],
            ]
        )
        result = _solve_correction(sim, law, t, x + scale * nav_error)
        dq = result.q_initial - sim.aim
        correct, ground = law.decide(dq)
        burn = correct & result.converged
        dv_command = jnp.where(burn, result.p, 0.0)
        k_exec = jax.random.fold_in(jax.random.fold_in(key, _EXECUTION), i)
        dv_exec = execute_burn(dv_command, err, jax.random.normal(k_exec, (3,)))
        dv_norm = _safe_norm(dv_exec)
        is_first = burn & (count == 0)
        x = x.at[3:].add(dv_exec)
        # Coast to the next fix (the last fix's state is the one propagated to encounter).
        t_next = jnp.where(i == sim.n_fixes - 1, t, t + sim.fix_interval_s)
        x, status = propagate(sim.model, t, x, t_next)
        carry = (
            x,
            dv_total + dv_norm,
            count + burn.astype(jnp.int32),
            ground_count + ground.astype(jnp.int32),
            failed | (correct & ~result.converged),
            jnp.where(is_first, dv_norm, first_dv),
            jnp.where(is_first, result.iterations, first_iter),
            prop_ok & (status == Status.ok),
        )
        rec = FixRecord(
            t, dq, dv_command, dv_exec, burn, ground, result.converged, result.iterations
        )
        return carry, (dv_norm, jnp.hypot(dq[0], dq[1]), rec)

    z, zi = jnp.zeros(()), jnp.zeros((), jnp.int32)
    if sim.guidance_enabled:
        carry0 = (x0, z, zi, zi, jnp.array(False), z, zi, jnp.array(True))
        carry, (dv_per_fix, b_pred, rec) = jax.lax.scan(fix, carry0, jnp.arange(sim.n_fixes))
        x_last, dv_total, count, ground_count, failed, first_dv, first_iter, prop_ok = carry
        t_last = t0 + (sim.n_fixes - 1) * sim.fix_interval_s
        q1, status1 = predict(sim, t_last, x_last)
        if sim.reference_dv:
            dv_ref = _safe_norm(_solve_correction(sim, law, t0, x0).p)
        else:
            dv_ref = first_dv
    else:
        q1, status1 = q0, status0
        dv_total, first_dv, dv_ref = z, z, z
        count, ground_count, first_iter = zi, zi, zi
        failed, prop_ok = jnp.array(False), jnp.array(True)
        dv_per_fix = jnp.zeros(sim.n_fixes)
        b_pred = jnp.full(sim.n_fixes, jnp.hypot(q0[0] - sim.aim[0], q0[1] - sim.aim[1]))
        rec = None

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
        dv_mps=dv_total,
        dv_first_mps=first_dv,
        dv_ref_mps=dv_ref,
        dv_increase_pct=jnp.where(dv_ref > 0.0, 100.0 * (dv_total / safe_ref - 1.0), 0.0),
        corrections=count,
        ground_calls=ground_count,
        iterations=first_iter,
        dv_per_fix_mps=dv_per_fix,
        predicted_b_err_m=b_pred,
        initial_position_error_m=dr,
        initial_velocity_error_mps=dv,
    )
    finite = all_finite(outcome)
    bad_status = jnp.maximum(status0, status1)
    converged = jnp.where(failed, Status.no_convergence, Status.ok)
    status = jnp.where(bad_status != Status.ok, bad_status, converged)
    status = jnp.where(~finite | ~prop_ok, Status.nan, status)
    outcome = outcome._replace(status=status.astype(jnp.int32))
    return outcome, (rec if record else None)


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
    return targeter.solve(q_function(sim, sim.t_first_fix_s, x), sim.aim, jnp.zeros(3))


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
    from ..dynamics.ephemeris import GM_SUN, planet_index, planet_state
    from ..geometry.bplane import check_b_plane_frame
    from ..geometry.kepler import propagate_kepler
    from ..geometry.lambert import solve_lambert

    # Only the model, epochs, aim and reference plane matter; everything else is reset so that
    # every scenario variant shares one compiled design function and one cached result.
    aim3 = jnp.concatenate([sim.aim[:2], jnp.zeros(1)])
    design = MidcourseSimulation(
        model=sim.model,
        r0_m=jnp.zeros(3),
        v0_mps=jnp.zeros(3),
        t_first_fix_s=sim.t_first_fix_s,
        fix_interval_s=jnp.asarray(86400.0),
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
    """Normal of the B-plane reference plane in EME2000 (SPEC §1)."""
    from ..dynamics.ephemeris import ECLIPTIC_POLE_EQUATORIAL, planet_index, planet_state

    if plane == "ecliptic":
        return jnp.asarray(ECLIPTIC_POLE_EQUATORIAL)
    if plane == "equator":
        return jnp.array([0.0, 0.0, 1.0])
    r, v = planet_state(planet_index("mars"), t_encounter_s)
    h = jnp.cross(r, v)
    return h / jnp.linalg.norm(h)


def build(scenario) -> tuple[MidcourseSimulation, AutonomousCorrection]:
    """Simulation data and correction rule of a validated midcourse :class:`Scenario` (SI).

    Designs the nominal transfer (`design_nominal`, cached) before returning; a nominal that
    cannot be targeted raises :class:`ScenarioError`.
    """
    import math

    from ..dynamics.ephemeris import GM_PLANETS
    from ..dynamics.heliocentric import SOLAR_PRESSURE_1AU
    from ..geometry.bplane import BPlaneError
    from ..scenario import ScenarioError
    from ..scenario.midcourse import epochs_s

    cfg = scenario.config
    mi, sc, dy, di, nv, ex, g, goal = (
        cfg[k]
        for k in (
            "mission",
            "spacecraft",
            "dynamics",
            "dispersion",
            "navigation",
            "execution",
            "guidance",
            "goal",
        )
    )
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    t = epochs_s(cfg)
    t_max = t["encounter_epoch"] + dy["window_days"] * 86400.0
    srp = sc["reflectivity"] * sc["srp_area_m2"] / sc["mass_kg"] if dy["srp"] else 0.0
    table = None
    if dy["ephemeris"] == "table":
        table = EphemerisTable.spanning(t["first_fix_epoch"], t_max)
    model = HeliocentricModel(
        ephemeris=table,
        gm_planets=f(GM_PLANETS if dy["planets"] else [0.0] * 8),
        srp_m2_per_kg=f(srp),
        solar_pressure_npm2=f(SOLAR_PRESSURE_1AU),
        rtol=f(dy["rtol"]),
        atol=f(dy["atol"]),
        solver=dy["solver"],
        max_steps=int(dy["max_steps"]),
    )
    aim_bt_br = f(mi["aim_b_km"]) * 1e3
    aim = jnp.stack([aim_bt_br[1], aim_bt_br[0]])  # Q order: (B_R, B_T[, t])
    if g["targets"] == "b_plane_tof":
        aim = jnp.concatenate([aim, jnp.zeros(1)])
    errors = MidcourseErrors(
        position_m=f(di["position_km"] * 1e3),
        velocity_mps=f(di["velocity_mps"]),
        position_offset_m=f(di["position_offset_km"]) * 1e3,
        velocity_offset_mps=f(di["velocity_offset_mps"]),
        nav_position_m=f(nv["position_sigma_km"] * 1e3),
        nav_velocity_mps=f(nv["velocity_sigma_mps"]),
        nav_position_bias_m=f(nv["position_bias_km"]) * 1e3,
        nav_velocity_bias_mps=f(nv["velocity_bias_mps"]),
        final_fix_scale=f(nv["final_fix_scale"]),
        magnitude_bias=f(ex["magnitude_bias_pct"] / 100.0),
        magnitude_sigma=f(ex["magnitude_sigma_pct"] / 100.0),
        pointing_sigma_rad=f(math.radians(ex["pointing_sigma_deg"])),
    )
    has_errors = any(
        v != 0.0
        for v in (
            nv["position_sigma_km"],
            nv["velocity_sigma_mps"],
            *nv["position_bias_km"],
            *nv["velocity_bias_mps"],
            ex["magnitude_bias_pct"],
            ex["magnitude_sigma_pct"],
            ex["pointing_sigma_deg"],
        )
    )
    sim = MidcourseSimulation(
        model=model,
        r0_m=jnp.zeros(3),
        v0_mps=jnp.zeros(3),
        t_first_fix_s=f(t["first_fix_epoch"]),
        fix_interval_s=f(nv["interval_days"] * 86400.0),
        t_encounter_s=f(t["encounter_epoch"]),
        t_max_s=f(t_max),
        aim=aim,
        ref_normal=reference_normal(mi["reference_plane"], t["encounter_epoch"]),
        goal=f([goal["b_km"] * 1e3, goal["tof_s"]]),
        errors=errors,
        n_fixes=int(nv["fixes"]),
        guidance_enabled=bool(g["enabled"]),
        reference_dv=bool(g["enabled"] and has_errors),
    )
    try:
        nominal = design_nominal(sim, t["launch_epoch"])
    except BPlaneError as error:
        raise ScenarioError(
            f"mission.reference_plane: {mi['reference_plane']!r}: {error}"
        ) from None
    except ValueError as error:
        raise ScenarioError(
            f"mission: {error}; allowed: epochs and aim point of a feasible transfer"
        ) from None
    sim = eqx.tree_at(lambda s: (s.r0_m, s.v0_mps), sim, (nominal.r0_m, nominal.v0_mps))
    tolerance = f([g["tolerance_b_km"] * 1e3, g["tolerance_b_km"] * 1e3, g["tolerance_tof_s"]])
    targeter = NewtonTargeter(
        tolerance=tolerance[: aim.shape[0]],
        epsilon=f(g["epsilon_mps"]),
        sensitivity=g["sensitivity"],
        iterations=int(g["iterations"]),
    )
    law = AutonomousCorrection(
        targeter=targeter,
        lower=f([g["lower_b_km"] * 1e3, g["lower_tof_s"]]),
        upper=f([g["upper_b_km"] * 1e3, g["upper_tof_s"]]),
    )
    return sim, law


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
    q = q_function(sim, sim.t_first_fix_s, x)
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

    def at(t):
        x, _ = propagate(sim.model, sim.t_first_fix_s, x0, t)
        out = {
            method: sensitivity(sim, method, t, x, epsilon)[1]
            for method in ("autodiff", "central_difference", "stm")
        }
        fixed = q_and_stm_jacobian_fixed_epoch(sim, t, x, t_end_s)
        out["stm_fixed_epoch"] = fixed(jnp.zeros(3))[1]
        return out

    return jax.vmap(at)(epochs_s)
