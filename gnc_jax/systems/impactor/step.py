"""The impactor's two loop steps on its :class:`~gnc_jax.systems.loop.LoopState`: the image
interval (image -> EKF update -> guidance ``plan`` -> control steps -> accelerometer noise ->
covariance propagation) and, inside it, the control step (guidance ``step`` -> engine -> RK4
truth step -> accelerometer -> EKF mean prediction)."""

import functools

import jax
import jax.numpy as jnp

from ..._numerics import (
    V3,
    as_array,
    as_arrays,
    as_components,
    computed_once,
    loop_shape,
    rarely,
)
from ..._random import fold_in
from ..._types import Array
from ...dynamics.impactor import rk4, tilt_direction
from ...navigation.camera import rotation_series, small_rotation_entries
from ...navigation.ekf import NIS_BOUND_2DOF, NavEstimate
from ...navigation.packed_ekf import apply_gain, propagate_packed
from ..loop import LoopState
from .draws import N_BURN_INTERVALS, ImpactorDraws, image_key_in, image_normals
from .navigation import accel_noise, camera_attitudes, image_update
from .state import Estimate, ImpactorSimulation, StepRecord


def _adjoint(sim: ImpactorSimulation, kind: str):
    """``computed_once``'s ``adjoint``: ``kind`` when ``sim`` is set up for reverse mode."""
    return kind if sim.reverse_mode else None


def _inline(fn, live, *args):
    """``fn(*args)``, left to XLA's fusion (the unfenced counterpart of computed_once)."""
    return fn(*args)


def command_and_thrust(sim: ImpactorSimulation, law, t, law_state, nav, engine):
    """The law's command at ``t`` and what the engine makes of it: ``(throttle, ignition,
    exec_magnitude, exec_pointing, thrust, law_state)``, the thrust (N, inertial) along the
    commanded direction tilted by the pointing error of the current firing and scaled by its
    magnitude error (an ignition takes the firing's errors from the interval's row of the
    burn table)."""
    ctx, err = sim.context, sim.errors
    # The command into memory before the engine reads it: left to fusion, the law's switch
    # is recomputed in each of the engine's outputs (the ignition and every thrust component).
    # Reverse mode recomputes this whole function in one fence instead (control_step).
    fence = _inline if sim.reverse_mode else computed_once
    command, law_state = fence(lambda s, n: law.step(s, n, t, ctx), t, law_state, nav)
    throttle = command.throttle
    ignition = (throttle > 0.0) & (engine.throttle_prev <= 0.0)
    first = engine.ignitions_image == 0
    exec_magnitude = jnp.where(
        ignition,
        jnp.where(first, engine.first_magnitude, engine.second_magnitude),
        engine.exec_magnitude,
    )
    exec_pointing = jnp.where(
        ignition,
        jnp.where(first, engine.first_pointing, engine.second_pointing),
        engine.exec_pointing,
    )
    direction = tilt_direction(command.direction, err.attitude_control_rad * exec_pointing)
    magnitude = sim.engine.thrust_n * (1.0 + err.burn_magnitude_frac * exec_magnitude)
    thrust = (throttle * magnitude) * direction
    return throttle, ignition, exec_magnitude, exec_pointing, thrust, law_state


def control_step(sim: ImpactorSimulation, law, accel_bias, record, state: LoopState, inputs):
    """One control step: guidance ``step`` -> engine -> RK4 truth -> accelerometer -> EKF mean.

    The truth's vectors are :class:`V3` here (see :func:`components`)."""
    ctx, err = sim.context, sim.errors
    dt = ctx.dt_s
    t, c_k = inputs  # c_k: s, weight of this step's Δv in the interval's end position
    estimate, engine, tally = state.estimate, state.actuator, state.tally
    # The command and the thrust, computed once per step into memory, not once per consumer
    # loop (see computed_once): the thrust feeds every component of the truth's RK4 step and
    # the accelerometer, which otherwise each recomputed its tilt and magnitude (measured:
    # the compiled step's elementwise operations per run 592 -> 316, the closed loop about
    # 10 % faster). In reverse mode the backward pass recomputes the law and the engine inside
    # a fence of their own (their residuals are ~100 arrays).
    throttle, ignition, exec_magnitude, exec_pointing, thrust, law_state = computed_once(
        lambda s, n, e: command_and_thrust(sim, law, t, s, n, e),
        t,
        state.law,
        estimate.nav,
        engine,
        adjoint=_adjoint(sim, "recompute"),
    )
    flow = throttle * sim.engine.mass_flow(1.0)
    # Fenced when the dynamics has terms to evaluate (four gravity evaluations per step, each
    # recomputed by every output's loop otherwise); without them the step is a few products
    # per component, cheaper left to fusion (measured 6 % of the loop).
    fence = computed_once if sim.dynamics.active else _inline
    truth = fence(lambda y, f, q: rk4(sim.dynamics, y, f, q, dt), t, state.truth, thrust, flow)
    # The accelerometer integrates the non-gravitational Δv while the engine fires; its white
    # noise reaches the estimate at the end of the interval (accel_noise).
    per_mass = dt / (0.5 * (state.truth.m + truth.m))
    dv_true = thrust * per_mass
    # |dv_true| without a square root: the tilted direction is a unit vector.
    magnitude = sim.engine.thrust_n * (1.0 + err.burn_magnitude_frac * exec_magnitude)
    dv_norm = (throttle * magnitude) * per_mass
    dv_meas = dv_true + (throttle * dt) * accel_bias
    # Straight-line mean propagation with the measured Δv applied uniformly (propagate_state).
    r_hat = estimate.r_hat + estimate.v_hat * dt + dv_meas * (0.5 * dt)
    v_hat = estimate.v_hat + dv_meas
    th2 = throttle * throttle
    ign = ignition.astype(engine.ignitions_image.dtype)
    moments = estimate.accel_moments
    new = LoopState(
        truth=truth,
        estimate=estimate._replace(
            r_hat=r_hat,
            v_hat=v_hat,
            accel_moments=(
                moments[0] + th2,
                moments[1] + th2 * c_k,
                moments[2] + th2 * c_k * c_k,
            ),
            burn_time_image_s=estimate.burn_time_image_s + throttle * dt,
        ),
        law=law_state,
        actuator=engine._replace(
            throttle_prev=throttle,
            exec_magnitude=exec_magnitude,
            exec_pointing=exec_pointing,
            ignitions_image=engine.ignitions_image + ign,
        ),
        tally=tally._replace(dv_mps=tally.dv_mps + dv_norm),
    )
    rec = None
    if record:
        rec = StepRecord(
            t, throttle, *(as_array(x) for x in (truth.r, truth.v, r_hat, v_hat)), law_state
        )
    return new, rec


def coast_step(sim: ImpactorSimulation, law, carry, inputs):
    """:func:`control_step` for a run whose engine stays off, and whether it did: the law's
    command, the truth's RK4 step without thrust and the estimate's straight-line mean, the
    full step's operations with a zero throttle (its zero Δv terms left out, which adds
    nothing); the engine's memory, the accelerometer and the tally are untouched.
    ``carry``: ``(state, fired)``, ``fired`` set once the law commands a throttle other than
    zero (the step is then not this one's: :func:`image_step` flies that run again on the
    full path)."""
    state, fired = carry
    ctx, dt = sim.context, sim.context.dt_s
    t, _ = inputs
    estimate = state.estimate
    # Not fenced: the command's only consumers are the law's state and the flag.
    command, law_state = law.step(state.law, estimate.nav, t, ctx)
    zero = jnp.zeros_like(state.truth.m)
    # rk4 itself with no thrust: the same bits as the full step's (a closed form of the
    # unpowered step measured 2 % faster but moved the last bits), fenced as there.
    fence = computed_once if sim.dynamics.active else _inline
    truth = fence(lambda y: rk4(sim.dynamics, y, V3(zero, zero, zero), zero, dt), t, state.truth)
    new = state._replace(
        truth=truth,
        estimate=estimate._replace(r_hat=estimate.r_hat + estimate.v_hat * dt),
        law=law_state,
        actuator=state.actuator._replace(throttle_prev=command.throttle),
    )
    return (new, fired | (command.throttle != 0.0)), None


def _flown(state: LoopState):
    """What an image interval's control steps change of the loop state: all that the
    two-pass interval gathers and writes back (the whole state through it measured the same
    speed but moved the last bits of the image updates' tally, fused otherwise)."""
    e = state.estimate
    return (
        state.truth,
        (e.r_hat, e.v_hat, e.accel_moments, e.burn_time_image_s),
        state.law,
        state.actuator,
        state.tally.dv_mps,
    )


def _with_flown(state: LoopState, flown) -> LoopState:
    truth, (r_hat, v_hat, moments, burn_time), law_state, engine, dv = flown
    return state._replace(
        truth=truth,
        estimate=state.estimate._replace(
            r_hat=r_hat, v_hat=v_hat, accel_moments=moments, burn_time_image_s=burn_time
        ),
        law=law_state,
        actuator=engine,
        tally=state.tally._replace(dv_mps=dv),
    )


def image_step(
    sim: ImpactorSimulation, law, draws: ImpactorDraws, record, state: LoopState, i, steps=None
):
    """One image interval: image -> EKF update -> guidance ``plan`` (:func:`begin_interval`) ->
    control steps -> accelerometer noise -> covariance propagation (:func:`end_interval`).

    ``steps``: the interval's control steps (static), ``sim.steps_per_image`` when ``None``;
    fewer for a last interval that ends at the cut-off."""
    dt = sim.context.dt_s
    n = sim.steps_per_image if steps is None else steps
    t = i * sim.context.image_interval_s
    state, row = begin_interval(sim, law, draws, state, i, t)
    k = jnp.arange(n)
    inputs = (t + dt * k, dt * (n - k - 0.5))
    # The truth state crosses the control steps as components (V3): its RK4 step then fuses
    # into few elementwise kernels (measured 12 % of the whole closed loop, results bit for bit
    # equal); the rest of the state stays in arrays, which the image step reads as vectors
    # and matrices (all of it as components measured slower overall).
    # Each control step is checkpointed too: reverse mode, recomputing an image interval,
    # keeps only the loop state per control step and recomputes the step inside its adjoint,
    # where XLA fuses the two, instead of writing every intermediate of the step to its own
    # stack (about 180 residual arrays a step, each its own kernel; measured 1.4x the reverse
    # pass). Without differentiation the checkpoint is inlined: the evaluation is unchanged.
    # Reverse mode carries the estimate's mean by component too, for a law that reads it so
    # (nav_by_component): the law gets its position and velocity as V3 (Estimate.nav) and the
    # adjoint of its step is elementwise over the batch, without the slices of (batch, 3)
    # arrays and their transposes (pads) that XLA on CPU runs as kernels of their own
    # (measured: the LOS law's adjoint 113 -> 90 kernels per control step, the gradient's CPU
    # time a quarter less). The values agree to rounding (last bits). A GPU's layout
    # (LoopShape.components) carries it so too: there each stacked vector under vmap is a
    # stack and a transpose kernel of its own (measured on an H100: the control step's loop
    # body 31 -> 14 kernels, deep-impact-los 25 % faster; see ImpactorSystem).
    step = jax.checkpoint(
        functools.partial(control_step, sim, law, draws.dispersion["accel_bias_mps2"], record),
        prevent_cse=False,
    )
    by_component = {"truth": as_components(state.truth)}
    if (sim.reverse_mode or loop_shape().components) and law.nav_by_component:
        by_component["estimate"] = as_components(state.estimate)
    start = state._replace(**by_component)
    unroll = loop_shape().unroll
    if loop_shape().rare and not (record or sim.reverse_mode or getattr(law, "relaxed", False)):
        # The engine fires in about 0.5 % of the control steps (deep-impact-los). Every run
        # first coasts through the interval; the runs whose law commanded thrust fly it again
        # on the full path, gathered (rarely). Each run's steps are those of the full loop
        # (8,192 runs: every outcome equal to the last bit).
        coast = functools.partial(coast_step, sim, law)
        (coasted, fired), _ = jax.lax.scan(
            coast, (start, jnp.zeros((), bool)), inputs, unroll=unroll
        )
        flown = rarely(
            fired,
            lambda s: _flown(jax.lax.scan(step, s[0], inputs, unroll=unroll)[0]),
            lambda s: _flown(s[1]),
            (start, coasted),
            loop_shape().rare,
        )
        inner, rec = _with_flown(coasted, flown), None
    else:
        inner, rec = jax.lax.scan(step, start, inputs, unroll=unroll)
    state = inner._replace(truth=as_arrays(inner.truth), estimate=as_arrays(inner.estimate))
    length_s = sim.context.image_interval_s if n == sim.steps_per_image else n * dt
    return end_interval(sim, state, row, length_s), rec


def begin_interval(
    sim: ImpactorSimulation, law, draws: ImpactorDraws, state: LoopState, i, t
) -> tuple[LoopState, Array]:
    """Image ``i`` at time ``t``: the EKF update, the law's ``plan``, the interval's
    accumulators reset and its row of the burn table (returned: its accelerometer normals are
    used at the interval's end) set for the engine's ignitions."""
    ctx = sim.context
    bias = draws.dispersion["attitude_bias_rad"]
    estimate, engine, tally = state.estimate, state.actuator, state.tally

    # The image's normals and the camera attitudes they set, computed once into memory: left
    # to fusion, XLA recomputes a value in every consumer's loop, and the attitudes' products
    # feed every entry of the filter update (measured 4x the image step's time). The update
    # itself is fenced for the same reason (its gain feeds the 21 covariance entries); the
    # front end's key is derived inside it, where XLA drops it when the front end draws
    # nothing (the Gaussian one). In reverse mode both keep their residuals from the forward
    # pass: recomputing them would draw their random numbers again (measured 10 % slower).
    # Inside, the normals' random bits go to memory before their transformation: drawn from
    # the written-out hash (no five-trip loop and its copies per image), which fused with the
    # inverse error function makes one slower kernel (measured: jax's loop 1.00, written out
    # and fused 1.03, written out and fenced 0.97 of the closed loop; the same numbers). Each
    # attitude error's rotation entries go to memory too, and the two 16-term series they
    # share before them: left to fusion, the series were recomputed for every component of
    # every row of both attitudes (measured 17 % of the closed loop's elementwise
    # operations), then for each of the nine entries (2-5 % of its time). Reverse mode keeps
    # this fence's residuals whole (no conditional inside it to transpose).
    rotation = _inline if sim.reverse_mode else computed_once

    def entries(theta):
        series = lambda th: rotation(rotation_series, t, th)  # noqa: E731
        return rotation(lambda th: small_rotation_entries(th, series), t, theta)

    def draws_and_attitudes(r_hat):
        bits_once = lambda fn: rotation(fn, t)  # noqa: E731
        w = rotation(lambda: image_normals(draws.image_stream, i, bits_once), t)
        return w, camera_attitudes(sim, r_hat, bias, w, draws.misalignment, entries)

    w, attitudes = computed_once(
        draws_and_attitudes, t, estimate.r_hat, adjoint=_adjoint(sim, "save")
    )
    gain, meas = computed_once(
        lambda *a: image_update(sim, *a, w[:2], fold_in(image_key_in(draws.image_stream, i), 1)),
        t,
        estimate.r_hat,
        estimate.v_hat,
        estimate.p,
        state.truth.r,
        attitudes,
        adjoint=_adjoint(sim, "save"),
    )
    p = apply_gain(estimate.p, gain.terms)
    # The covariance in the packed form the filter carries: a law's plan reads its entries
    # (``nav.p[i, j]``) where they are; no 6x6 matrix is assembled for it.
    nav = NavEstimate(jnp.concatenate([gain.r, gain.v]), p)
    law_state = law.plan(state.law, nav, t, ctx)
    outside = (meas.valid & (gain.nis > NIS_BOUND_2DOF)).astype(tally.innovations_outside.dtype)
    los_error_sq = jnp.where(meas.valid, jnp.sum((meas.z - meas.z_true) ** 2), 0.0)
    z = jnp.zeros(())
    row = draws.burns[engine.burn_intervals % N_BURN_INTERVALS]
    state = LoopState(
        truth=state.truth,
        estimate=Estimate(
            r_hat=gain.r, v_hat=gain.v, p=p, accel_moments=(z, z, z), burn_time_image_s=z
        ),
        law=law_state,
        actuator=engine._replace(
            first_magnitude=row[0],
            first_pointing=row[1:4],
            second_magnitude=row[4],
            second_pointing=row[5:8],
            ignitions_image=jnp.zeros_like(engine.ignitions_image),
        ),
        tally=tally._replace(
            los_error_sq=tally.los_error_sq + los_error_sq,
            images_used=tally.images_used + meas.valid.astype(tally.images_used.dtype),
            innovations_outside=tally.innovations_outside + outside,
        ),
    )
    return state, row


def end_interval(sim: ImpactorSimulation, state: LoopState, row, length_s: float) -> LoopState:
    """The end of an image interval of ``length_s`` seconds: the accelerometer's white noise
    reaches the estimate (:func:`~.navigation.accel_noise`, from ``row[8:14]`` of the burn
    table), the covariance grows, and the interval's burn and firings are counted."""
    ctx, err = sim.context, sim.errors
    dt = ctx.dt_s
    estimate, engine, tally = state.estimate, state.actuator, state.tally
    burned = estimate.accel_moments[0] > 0.0
    dr, dv = accel_noise(err.accel_noise_mps2 * dt, estimate.accel_moments, row[8:14])
    # Covariance: straight-line growth over the interval plus the accelerometer's Δv error.
    tb = estimate.burn_time_image_s
    model = sim.noise_model
    q_dv = model.accel_noise_mps2**2 * dt * tb + model.accel_bias_mps2**2 * tb**2
    p = propagate_packed(estimate.p, length_s, sim.process_noise_m2s3, q_dv)
    return state._replace(
        estimate=estimate._replace(r_hat=estimate.r_hat + dr, v_hat=estimate.v_hat + dv, p=p),
        actuator=engine._replace(
            burn_intervals=engine.burn_intervals + burned.astype(engine.burn_intervals.dtype)
        ),
        # the interval's totals (fewer outputs per control step: each is a kernel)
        tally=tally._replace(
            firings=tally.firings + engine.ignitions_image, burn_time_s=tally.burn_time_s + tb
        ),
    )


__all__ = ["begin_interval", "control_step", "end_interval", "image_step"]
