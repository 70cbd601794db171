"""Closed-loop impactor terminal-phase simulation: truth, camera, EKF, guidance, engine.

One trajectory per call (`simulate`); Monte Carlo batches ``vmap`` it over per-run keys.
Time is mission time from the start of the approach (s). Two nested ``lax.scan`` loops: the
outer one at the image interval (image -> EKF update -> guidance ``plan``), the inner one at the
control step (guidance ``step`` -> engine -> RK4 truth step -> accelerometer -> EKF prediction),
both in :mod:`.step`. The run ends at the guidance cut-off; the truth then coasts to the
B-plane.

``simulate`` is :func:`~gnc_jax.systems.loop.closed_loop` of :func:`start` (the dispersed
start and the run's draws, :mod:`.draws`), :func:`run` (the scans) and :func:`finish` (the
coast, the outcome and its status). The loop state is a
:class:`~gnc_jax.systems.loop.LoopState` of the truth, the filter's :class:`~.state.Estimate`,
the law's state, the :class:`~.state.EngineMemory` and the :class:`~.state.ImpactorTally`.
"""

import functools

import jax
import jax.numpy as jnp

from ..._status import Status
from ..._types import Array, Float, PRNGKeyArray
from ...dynamics.impactor import coast_to_b_plane
from ...geometry.ellipse import b_plane_position_covariance, mean_position_error
from ...geometry.silhouette import focusing_factor, silhouette_matrix, silhouette_ratio
from ...guidance.impactor.base import AbstractImpactorGuidance
from ...navigation.ekf import navigation_lost
from ...navigation.packed_ekf import pack
from ..loop import LoopState, closed_loop, flatten_trace, with_status
from .draws import (
    ImpactorDraws,
    burn_draws,
    camera_misalignment,
    image_stream,
    initial_conditions,
)
from .state import (
    EngineMemory,
    Estimate,
    ImpactorOutcome,
    ImpactorSimulation,
    ImpactorTally,
    StepRecord,
)
from .step import image_step


def start(
    sim: ImpactorSimulation, law: AbstractImpactorGuidance, key: PRNGKeyArray
) -> tuple[LoopState, ImpactorDraws]:
    """The loop state at t = 0 (the dispersed truth, the filter from the knowledge errors, the
    law's initial state, the engine off, nothing counted) and the run's fixed draws."""
    truth0, nav0, dispersion = initial_conditions(sim, key)
    burns = burn_draws(key)
    z = jnp.zeros(())
    i0 = jnp.zeros((), jnp.int32)
    z3 = jnp.zeros(3)
    state = LoopState(
        truth=truth0,
        estimate=Estimate(
            r_hat=nav0.r, v_hat=nav0.v, p=pack(nav0.p), accel_moments=(z, z, z), burn_time_image_s=z
        ),
        law=law.init(nav0, sim.context),
        actuator=EngineMemory(
            throttle_prev=z,
            exec_magnitude=z,
            exec_pointing=z3,
            first_magnitude=z,
            first_pointing=z3,
            second_magnitude=z,
            second_pointing=z3,
            ignitions_image=i0,
            burn_intervals=i0,
        ),
        tally=ImpactorTally(
            dv_mps=z,
            firings=jnp.zeros((), jnp.int32),
            burn_time_s=z,
            los_error_sq=z,
            images_used=jnp.zeros((), jnp.int32),
            innovations_outside=jnp.zeros((), jnp.int32),
        ),
    )
    misalignment = camera_misalignment(sim, key) if sim.camera_misaligned else None
    return state, ImpactorDraws(dispersion, burns, misalignment, image_stream(key))


def run(
    sim: ImpactorSimulation,
    law: AbstractImpactorGuidance,
    key: PRNGKeyArray,
    draws: ImpactorDraws,
    state: LoopState,
    record: bool,
) -> tuple[LoopState, StepRecord | None]:
    """Guidance up to the cut-off: one :func:`~.step.image_step` per image, each with its
    control steps; the trace at the control rate.

    Each image step is checkpointed: reverse mode keeps one loop state per image and
    recomputes an image's control steps on the way back, so its memory is that of one image
    interval plus a carry per image instead of every control step's residuals; the control
    steps are checkpointed inside it (:func:`~.step.image_step`), so that recomputation keeps
    one loop state per control step. Without differentiation the checkpoints are inlined: the
    evaluation is unchanged.

    An image interval that does not divide the time to the cut-off leaves a last interval of
    ``steps_per_image - steps_after_cutoff`` control steps, run after the scan: the loop ends
    at the cut-off, and the truth never flies past the target before the coast."""

    def interval(steps):
        step = functools.partial(image_step, sim, law, draws, record, steps=steps)
        return jax.checkpoint(step, prevent_cse=False)

    shortened = sim.steps_after_cutoff > 0
    full = sim.n_images - int(shortened)
    state, rec = jax.lax.scan(interval(sim.steps_per_image), state, jnp.arange(full))
    trace = flatten_trace(rec)
    if shortened:
        last = interval(sim.steps_per_image - sim.steps_after_cutoff)
        state, last_rec = last(state, jnp.asarray(full))
        if record:
            trace = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), trace, last_rec)
    return state, trace


def finish(
    sim: ImpactorSimulation,
    law: AbstractImpactorGuidance,
    key: PRNGKeyArray,
    draws: ImpactorDraws,
    state: LoopState,
) -> ImpactorOutcome:
    """Coast the truth to the B-plane and collect the run's results with their status."""
    ctx, tally = sim.context, state.tally
    b, _ = coast_to_b_plane(sim.dynamics, state.truth, ctx.c_bi, sim.coast_steps)
    miss = b - ctx.aim_final_m
    nav = state.estimate.nav
    t_go = jnp.linalg.norm(nav.r) / jnp.linalg.norm(nav.v)
    sigma_b = mean_position_error(b_plane_position_covariance(nav.p, t_go, ctx.c_bi))
    outcome = ImpactorOutcome(
        status=jnp.zeros((), jnp.int32),
        miss_m=jnp.linalg.norm(miss),
        miss_t_m=miss[0],
        miss_r_m=miss[1],
        b_t_m=b[0],
        b_r_m=b[1],
        dv_mps=tally.dv_mps,
        firings=tally.firings,
        burn_time_s=tally.burn_time_s,
        fuel_kg=sim.mass_kg - state.truth.m,
        nav_position_error_m=jnp.linalg.norm(nav.r - state.truth.r),
        nav_sigma_b_m=sigma_b,
        **draws.dispersion,
        los_error_rms_urad=1e6
        * jnp.sqrt(tally.los_error_sq / jnp.maximum(2 * tally.images_used, 1)),
        images_rejected=(sim.n_images - tally.images_used).astype(jnp.int32),
        silhouette_ratio=silhouette_ratio(b, _silhouette(sim), _focusing(sim)),
        innovations_outside=tally.innovations_outside,
    )
    # A run whose navigation was lost ends nav_lost, ahead of what it then does to its fuel and
    # its miss; a law whose own solve failed (a burn's Newton iteration) ends no_convergence;
    # a run out of propellant reads so ahead of the miss that follows from it.
    lost = navigation_lost(sim.n_images, tally.images_used, tally.innovations_outside)
    failures = (
        (lost, Status.nav_lost),
        (~law.converged(state.law), Status.no_convergence),
        (outcome.fuel_kg > sim.propellant_kg, Status.propellant),
        (outcome.miss_m > sim.miss_limit_m, Status.missed),
    )
    return with_status(outcome, failures)


def _silhouette(sim: ImpactorSimulation):
    """The target's shadow along S in the B-plane (m^2, :mod:`gnc_jax.geometry.silhouette`)."""
    return silhouette_matrix(sim.target.semi_axes_m, sim.target.c_bi, sim.context.c_bi)


def _focusing(sim: ImpactorSimulation):
    speed = jnp.linalg.norm(sim.v0_mps)
    return focusing_factor(sim.dynamics.mu_target, sim.target.mean_radius_m, speed)


def capture_silhouette(sim: ImpactorSimulation) -> Float[Array, "2 2"]:
    """The B-plane ellipse (shape matrix, m^2) whose inside is a hit: the silhouette widened
    by gravitational focusing."""
    return _silhouette(sim) * _focusing(sim) ** 2


def simulate(
    sim: ImpactorSimulation,
    law: AbstractImpactorGuidance,
    key: PRNGKeyArray,
    record: bool = False,
) -> tuple[ImpactorOutcome, StepRecord | None]:
    """Simulate one closed-loop impactor approach.

    Args:
        sim: scenario data (see :class:`~.state.ImpactorSimulation`).
        law: guidance law (an :class:`AbstractImpactorGuidance`).
        key: this run's key, ``jax.random.fold_in(root, run_index)``.
        record: also return the control-rate :class:`~.state.StepRecord` trace (static).

    Returns:
        ``(outcome, trace)``; ``trace`` is ``None`` unless ``record``.
    """


# The signature and docstring above; the body is the shared skeleton of start, run, finish.
simulate = functools.wraps(simulate)(closed_loop(start, run, finish))


__all__ = [
    "ImpactorOutcome",
    "ImpactorSimulation",
    "StepRecord",
    "capture_silhouette",
    "finish",
    "run",
    "simulate",
    "start",
]
