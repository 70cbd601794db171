"""Closed-loop deep-space intercept with augmented PN and pulse firing (seed 004).

One trajectory per call (`simulate`); Monte Carlo batches ``vmap`` it over per-run keys. Time
is mission time from the Table 2 initial state (s). Nested ``lax.scan`` loops: blocks of
``DRAW_BLOCK`` images (their normals drawn at once), the LOS-measurement interval (camera
angles -> EKF update, in the packed form of ``navigation.packed_ekf``), and the guidance step
(APN command -> Schmitt trigger -> pulse -> drift-kick-drift truth step of the heliocentric
intercept dynamics -> EKF mean prediction; no loop when there is one step per image). Guidance stops
``coast_s`` before the nominal impact; the truth then coasts to the B-plane, where the miss is
measured (aim: the target's centre).

Navigation (seed 004 Table 4 knowledge errors): the paper's Monte Carlo uses initial position
knowledge (100, 10) km, velocity knowledge 0.1 m/s and a 320 urad attitude measurement error,
but does not describe its navigation. gnc_jax closes the loop with the impactor's camera,
LOS front end and EKF (navigation/camera.py, navigation/measurements/gaussian.py,
navigation/ekf.py): the filter starts from the knowledge errors (drawn per run, along / across
the initial LOS), takes the target's LOS angles at every guidance step (the paper's loop
recomputes the LOS at every step, Fig. 4) with the attitude error as white angle noise, and
predicts with straight-line motion plus the modelled differential gravity and the executed Δv
(no accelerometer error in Table 4). The same attitude error tilts each firing's thrust.
``navigation.model = "perfect"`` feeds the law the true state (the paper's error-free Table 3
runs).
"""

import functools

import jax
import jax.numpy as jnp

from ..._numerics import as_arrays, as_components, loop_shape, safe_norm
from ..._status import Status
from ..._types import PRNGKeyArray
from ...dynamics.intercept import coast_to_b_plane
from ...geometry.silhouette import focusing_factor
from ...guidance.intercept.apn import AugmentedPNGuidance
from ...navigation.ekf import navigation_lost
from ..loop import LoopState, closed_loop, flatten_trace, scan_in_blocks, with_status
from .draws import (
    DRAW_BLOCK,
    InterceptDraws,
    block_draws,
    image_draws_of,
    knowledge_errors,
    pointing_draws,
)
from .guidance_step import guidance_step
from .navigation import image_update, initial_estimate
from .state import PNOutcome, PNRecord, PNSimulation, PulseActuator, PulseTally


def start(
    sim: PNSimulation, law: AugmentedPNGuidance, key: PRNGKeyArray
) -> tuple[LoopState, InterceptDraws]:
    """The loop state at t = 0 (nominal truth, the filter from the knowledge errors, the
    law's initial state, engine off, nothing counted) and the run's fixed draws."""
    know_pos, know_vel = knowledge_errors(sim, key)
    draws = InterceptDraws(know_pos, know_vel, pointing_draws(key))
    z, zi = jnp.zeros(()), jnp.zeros((), jnp.int32)
    state = LoopState(
        truth=sim.y0,
        estimate=() if sim.nav_model == "perfect" else initial_estimate(sim, know_pos, know_vel),
        law=law.init(None, sim.context),
        actuator=PulseActuator(direction_prev=jnp.zeros(3), pointing_error=jnp.zeros(2)),
        tally=PulseTally(
            dv_mps=z,
            firings=zi,
            ignitions=zi,
            pulses=zi,
            last_firing_s=z,
            images_used=zi,
            innovations_outside=zi,
        ),
    )
    return state, draws


def _image_step(
    sim: PNSimulation, law: AugmentedPNGuidance, key, pointing_table, record, state, inputs
):
    """One measurement interval: LOS image -> EKF update -> guidance steps -> covariance.

    ``inputs``: the image index and its column of :func:`~.draws.block_draws` (one array per
    row)."""
    i, column = inputs
    dt = sim.context.dt_s
    t = i * (dt * sim.steps_per_image)
    w = image_draws_of(column, sim.planar)
    if sim.nav_model != "perfect":
        estimate, used, outside = image_update(
            sim, key, i, t, state.estimate, state.truth.r, w.measurement
        )
        tally = state.tally
        state = state._replace(
            estimate=estimate,
            tally=tally._replace(
                images_used=tally.images_used + used.astype(jnp.int32),
                innovations_outside=tally.innovations_outside + outside.astype(jnp.int32),
            ),
        )
    step = functools.partial(guidance_step, sim, law, pointing_table, record)
    if sim.steps_per_image == 1:  # one step per image: no inner loop (and its carry copies)
        state, rec = step(state, jnp.asarray(t, float))
        rec = jax.tree_util.tree_map(lambda x: x[None], rec)
    else:
        state, rec = jax.lax.scan(step, state, t + dt * jnp.arange(sim.steps_per_image))
    return state, rec


def run(
    sim: PNSimulation,
    law: AugmentedPNGuidance,
    key: PRNGKeyArray,
    draws: InterceptDraws,
    state: LoopState,
    record: bool,
) -> tuple[LoopState, PNRecord | None]:
    """Guidance up to the cutoff: the images in blocks of ``DRAW_BLOCK`` (their normals drawn
    at once), each with its guidance steps; the trace at the guidance rate."""
    # checkpointed: reverse mode keeps one loop state per image (see scan_in_blocks)
    image_step = jax.checkpoint(
        functools.partial(_image_step, sim, law, key, draws.pointing, record), prevent_cse=False
    )

    def block_inputs(b, length):  # the image indices and their normals, one array per row
        w = block_draws(key, b, sim.planar)
        return b * DRAW_BLOCK + jnp.arange(length), tuple(row[:length] for row in w)

    # On an accelerator the loop carries its 3-vectors by component (V3, LoopShape.components):
    # the guidance step and the filter's update are then elementwise over the batch, with no
    # stack and transpose kernel per vector and step (the same arithmetic, rounded alike to
    # the family's batch_tolerance).
    if loop_shape().components:
        state = _by_component(state)
    state, rec = scan_in_blocks(image_step, state, sim.n_images, DRAW_BLOCK, block_inputs)
    return as_arrays(state), flatten_trace(rec)  # (images, steps per image) -> guidance steps


def _by_component(state: LoopState) -> LoopState:
    """The run's 3-vectors as :class:`~gnc_jax._numerics.V3`; the target's ephemeris, the same
    for every run (not batched under ``vmap``), stays a (3,) array: one loop value each, not
    three."""
    truth = state.truth
    state = as_components(state._replace(truth=truth._replace(r_target=None, v_target=None)))
    return state._replace(
        truth=state.truth._replace(r_target=truth.r_target, v_target=truth.v_target)
    )


def finish(
    sim: PNSimulation,
    law: AugmentedPNGuidance,
    key: PRNGKeyArray,
    draws: InterceptDraws,
    state: LoopState,
) -> PNOutcome:
    """The coast to the B-plane and the outcome: ``nan`` when a field is not finite, else
    ``nav_lost`` when the filter lost the target (``navigation.ekf.navigation_lost``: most
    images unused or beyond their innovation bound), ``out_of_domain`` when the B-plane miss
    exceeds the initial range (the run ends farther from the target than it started: no
    intercept), ``time_out`` when the B-plane is not reached ahead, ``no_convergence`` when
    the law's own solve failed (:meth:`~gnc_jax.guidance.base.AbstractGuidanceLaw.converged`;
    the packaged laws solve nothing), ``propellant`` when the run burned more than
    ``sim.propellant_kg``, ``missed`` when the miss exceeds ``sim.miss_limit_m``, the
    delivery tolerance."""
    truth, tally = state.truth, state.tally
    perfect = sim.nav_model == "perfect"
    one = jnp.ones((), jnp.int32)
    b, t_rest = coast_to_b_plane(sim.dynamics, truth, sim.c_bi, sim.coast_steps)
    nav_r = truth.r if perfect else state.estimate.r_hat
    outcome = PNOutcome(
        status=jnp.zeros((), jnp.int32),
        miss_m=safe_norm(b),
        miss_t_m=b[0],
        miss_r_m=b[1],
        dv_mps=tally.dv_mps,
        firings=tally.firings,
        ignitions=tally.ignitions,
        pulses=tally.pulses,
        last_firing_s=tally.last_firing_s,
        fuel_kg=sim.y0.m - truth.m,
        nav_position_error_m=jnp.linalg.norm(nav_r - truth.r),
        knowledge_position_error_m=draws.knowledge_position_m,
        knowledge_velocity_error_mps=draws.knowledge_velocity_mps,
        silhouette_ratio=safe_norm(b)
        / (
            sim.dynamics.target_radius_m
            * focusing_factor(
                sim.dynamics.mu_target, sim.dynamics.target_radius_m, safe_norm(sim.y0.v)
            )
        ),
        images_rejected=(0 if perfect else sim.n_images - tally.images_used) * one,
        innovations_outside=tally.innovations_outside,
    )
    # A run whose navigation was lost ends nav_lost, ahead of what it then does to its miss and
    # fuel (a perfect navigation model takes no image).
    lost = (
        jnp.asarray(False)
        if perfect
        else navigation_lost(sim.n_images, tally.images_used, tally.innovations_outside)
    )
    # ``not (t_rest > 0)`` rather than ``t_rest <= 0``: a NaN coast time is a time-out too.
    failures = (
        (lost, Status.nav_lost),
        (outcome.miss_m > sim.context.range0_m, Status.out_of_domain),
        (~(t_rest > 0.0), Status.time_out),
        (~law.converged(state.law), Status.no_convergence),
        (outcome.fuel_kg > sim.propellant_kg, Status.propellant),
        (outcome.miss_m > sim.miss_limit_m, Status.missed),
    )
    return with_status(outcome, failures)


def simulate(
    sim: PNSimulation, law: AugmentedPNGuidance, key: PRNGKeyArray, record: bool = False
) -> tuple[PNOutcome, PNRecord | None]:
    """Simulate one closed-loop intercept.

    Args:
        sim: scenario data (:class:`~.state.PNSimulation`).
        law: :class:`~gnc_jax.guidance.intercept.apn.AugmentedPNGuidance`.
        key: this run's key, ``jax.random.fold_in(root, run_index)``.
        record: also return the guidance-rate :class:`~.state.PNRecord` trace (static).
    """


# The signature and docstring above; the body is the shared skeleton of start, run, finish.
simulate = functools.wraps(simulate)(closed_loop(start, run, finish))


__all__ = [
    "PNOutcome",
    "PNRecord",
    "PNSimulation",
    "finish",
    "run",
    "simulate",
    "start",
]
