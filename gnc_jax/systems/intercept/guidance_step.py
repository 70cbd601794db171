"""One guidance step of the intercept: APN command -> Schmitt trigger -> pulse -> truth step
(``drift_kick_drift_step`` of the heliocentric intercept dynamics) -> EKF mean, and the tally
of the pulses fired."""

import jax.numpy as jnp

from ..._numerics import V3, as_array, as_v3, computed_once, cross3, dot3, norm3, safe_norm
from ...dynamics.impactor import perturb_direction
from ...dynamics.intercept import drift_kick_drift_step
from ...guidance.intercept.apn import AugmentedPNGuidance, PNNavigation
from ..loop import LoopState
from .draws import N_IGNITION_DRAWS
from .navigation import predict_mean
from .state import Estimate, PNRecord, PNSimulation, PulseActuator


def guidance_step(
    sim: PNSimulation,
    law: AugmentedPNGuidance,
    pointing_table,
    record: bool,
    state: LoopState,
    t,
) -> tuple[LoopState, PNRecord | None]:
    """The loop state one guidance step (``sim.context.dt_s``) after ``state`` at time ``t``,
    and the step's :class:`~.state.PNRecord` when ``record``. ``pointing_table``: the run's
    ignition pointing normals (:func:`~.draws.pointing_draws`).

    The state's 3-vectors are (3,) arrays, or :class:`~gnc_jax._numerics.V3` in an
    accelerator's layout (``simulation.run``): the step is then elementwise arithmetic on
    per-run scalars, with no 3-vector stacked under ``vmap``."""
    ctx, err = sim.context, sim.errors
    dt = ctx.dt_s
    perfect = sim.nav_model == "perfect"
    truth, actuator, tally = state.truth, state.actuator, state.tally
    if perfect:
        r_hat, v_hat = truth.r, truth.v
    else:
        r_hat, v_hat = state.estimate.r_hat, state.estimate.v_hat
    navsol = PNNavigation(r_hat, v_hat, truth.r_target)

    def law_and_gravity(law_state_in, nav):
        # The filter's modelled gravity at the estimate is the law's A_r (eq. 10) before its
        # projection: computed in the same branch, XLA evaluates it once for both.
        command, law_state = law.step(law_state_in, nav, t, ctx)
        g = None if perfect else ctx.dynamics.relative_gravity(nav.r_target, nav.r)
        if not record:  # the command and N are diagnostics of the trace only: carried
            # unchanged, loop invariants that XLA drops from the loop
            law_state = law_state._replace(
                command_mps2=law_state_in.command_mps2, coefficient=law_state_in.coefficient
            )
        return command, law_state, g

    # Once per step, not once per consumer loop (see _numerics.computed_once).
    command, law_state, g = computed_once(law_and_gravity, t, state.law, navsol)
    on, on_prev = law_state.engine_on, state.law.engine_on  # the trigger now and a step ago
    ignition = (on > 0.5) & (on_prev <= 0.5)
    fresh = err.attitude_rad * pointing_table[tally.ignitions % N_IGNITION_DRAWS]
    pointing = jnp.where(ignition, fresh, actuator.pointing_error)

    def engine_and_truth(truth, d, throttle, pointing):
        if sim.planar:  # rotate within the orbit plane about its normal
            tilted = d + pointing[0] * cross3(ctx.reference_normal, d)
            direction = tilted / norm3(tilted)
        else:
            direction = perturb_direction(as_array(d), pointing)
            direction = as_v3(direction) if isinstance(d, V3) else direction
        thrust = throttle * sim.engine.thrust_n * direction
        flow = throttle * sim.engine.mass_flow(1.0)
        return direction, thrust, drift_kick_drift_step(sim.dynamics, truth, thrust, flow, dt)

    direction, thrust, new_truth = computed_once(
        engine_and_truth, t, truth, command.direction, command.throttle, pointing
    )
    dv = thrust * (dt / (0.5 * (truth.m + new_truth.m)))
    estimate = state.estimate
    if not perfect:
        # Executed Δv (perfect accelerometer) plus the modelled gravity over the step.
        r_hat, v_hat = predict_mean(r_hat, v_hat, dv + g * dt, dt)
        estimate = Estimate(r_hat, v_hat, estimate.p)
    fired = on > 0.5
    # A firing is one pulse train of one thruster direction: reversing the thrust (the
    # opposite thrusters) while the trigger stays on starts a new firing.
    reversal = fired & (on_prev > 0.5) & (dot3(direction, actuator.direction_prev) < 0)
    new = LoopState(
        truth=new_truth,
        estimate=estimate,
        law=law_state,
        actuator=PulseActuator(direction_prev=direction, pointing_error=pointing),
        tally=tally._replace(
            dv_mps=tally.dv_mps + safe_norm(dv),
            firings=tally.firings + (ignition | reversal).astype(jnp.int32),
            ignitions=tally.ignitions + ignition.astype(jnp.int32),
            pulses=tally.pulses + fired.astype(jnp.int32),
            last_firing_s=jnp.where(fired, t, tally.last_firing_s),
        ),
    )
    rec = None
    if record:
        r_m, a_cmd = as_array(truth.r), as_array(law_state.command_mps2)
        rec = PNRecord(t, on, a_cmd, law_state.coefficient, norm3(r_m), r_m)
    return new, rec


__all__ = ["guidance_step"]
