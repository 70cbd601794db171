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
import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._numerics import computed_once, cross3, dot3, norm3, safe_norm
from ..._random import stream_key, stream_normal
from ..._status import Status
from ..._types import Array, Float, Matrix3, PRNGKeyArray, Scalar, Vector3
from ...dynamics.impactor import Engine, perturb_direction
from ...dynamics.intercept import (
    InterceptDynamics,
    InterceptState,
    coast_to_b_plane,
    drift_kick_drift_step,
)
from ...geometry.bplane import b_plane_frame
from ...geometry.kepler import OrbitalElements, elements_to_state
from ...geometry.silhouette import focusing_factor
from ...guidance.intercept.apn import (
    AugmentedPNGuidance,
    PNGuidanceContext,
    PNNavigation,
)
from ...navigation.camera import camera_axes
from ...navigation.ekf import NavEstimate
from ...navigation.measurements import AbstractMeasurement, Exposure, GaussianLOSMeasurement
from ...navigation.packed_ekf import (
    FULL,
    PLANAR,
    PackedCovariance,
    apply_gain,
    los_gain,
    pack,
    predict_los_packed,
    propagate_packed,
    unpack,
)
from ..loop import flatten_trace, scan_in_blocks, with_status
from .params import InterceptParameters, PNErrors, parameters


class PNSimulation(eqx.Module):
    """Everything one intercept run needs except the guidance law and the random key.

    Attributes:
        y0: nominal initial truth (target heliocentric, impactor relative, mass).
        context: on-board data of the law; dynamics: true force model; engine: true engine.
        errors: 1-sigma error sources; process_noise_m2s3: filter white-acceleration density.
        c_bi: B-plane frame (S, T, R) of the nominal approach; los_frame0: rows (along LOS,
            across it in the orbit plane, out of plane) at t = 0, for the knowledge errors.
        planar: keep every error in the orbit plane (static); nav_model: "ekf" or "perfect".
        n_images, steps_per_image, coast_steps: loop sizes (static).
        measurement: the LOS front end (Gaussian angle noise of the attitude error, zero out
            of plane when planar).
    """

    y0: InterceptState
    context: PNGuidanceContext
    dynamics: InterceptDynamics
    engine: Engine
    errors: PNErrors
    process_noise_m2s3: Scalar
    c_bi: Matrix3
    los_frame0: Matrix3
    measurement: AbstractMeasurement
    planar: bool = eqx.field(static=True)
    nav_model: str = eqx.field(static=True)
    n_images: int = eqx.field(static=True)
    steps_per_image: int = eqx.field(static=True)
    coast_steps: int = eqx.field(static=True, default=60)


class PNOutcome(NamedTuple):
    """Per-run results. B-plane miss components relative to the target's centre."""

    status: Array  # int, Status
    miss_m: Scalar
    miss_t_m: Scalar
    miss_r_m: Scalar
    dv_mps: Scalar  # total Δv magnitude (sum over pulses)
    firings: Array  # int, pulse trains: a new one at each ignition or thrust reversal
    ignitions: Array  # int, trigger off -> on transitions
    pulses: Array  # int, guidance steps with the engine on
    last_firing_s: Scalar  # mission time of the last pulse (0 if none)
    fuel_kg: Scalar
    nav_position_error_m: Scalar  # |r_hat - r| at the end of guidance
    knowledge_position_error_m: Vector3  # along LOS, across in-plane, out of plane
    knowledge_velocity_error_mps: Vector3  # same axes
    # B-plane miss over the capture radius of the spherical target (< 1: a hit, see
    # gnc_jax.geometry.silhouette)
    silhouette_ratio: Scalar


class PNRecord(NamedTuple):
    """Guidance-rate trace of one run (Figs. 7-9)."""

    t_s: Scalar
    engine_on: Scalar
    command_mps2: Vector3  # continuous APN command A (eq. 11)
    coefficient: Scalar  # N (eq. 12)
    range_m: Scalar
    r_m: Vector3


class _Carry(NamedTuple):
    """State of one run between guidance steps (the estimate carried as ``r_hat``, ``v_hat``:
    see ``simulation.impactor._Carry``)."""

    truth: InterceptState
    r_hat: Vector3
    v_hat: Vector3
    p: PackedCovariance  # the 21 unique entries of the 6x6 covariance (10 when planar)
    law_state: tuple
    on_prev: Scalar
    direction_prev: Vector3
    pointing_error: Float[Array, "2"]
    dv_mps: Scalar
    firings: Array
    ignitions: Array
    pulses: Array
    last_firing_s: Scalar


# Random streams: once per run the knowledge errors and a table of pointing errors, one row
# per ignition (stream _IGNITIONS: the k-th ignition of the run takes row k, cyclically past
# N_IGNITION_DRAWS; one angle about the orbit normal when planar, two in 3-D); once per block
# of DRAW_BLOCK images (stream _IMAGES, index = block) the LOS measurement noise of its images,
# one row per angle (the in-plane one, and the out-of-plane one in 3-D) and one column per
# image. Nothing is drawn per guidance step, and only what a step uses: the paper scenario
# ignites about 53 times in 91,200 steps, so drawing a pointing error at every image cost as
# much as its measurement noise (8 ns of a 150 ns step). A block, not an image, per draw:
# jax's threefry hash runs as a five-trip loop on CPU, whose fixed cost per call is then shared
# by DRAW_BLOCK images.
_KNOW_POS, _KNOW_VEL, _IMAGES, _IGNITIONS, _FRONT_END = range(5)
DRAW_BLOCK = 64
N_IGNITION_DRAWS = 128
"""Rows of the per-run pointing table (measured: at most 67 ignitions per run in 2000 runs of
``bennu-apn``, 103 in 500 of ``bennu-apn-3d``); a run that ignites more reuses them in order."""


class ImageDraws(NamedTuple):
    """Standard normals of one image (float32 draws: 24-bit normals are ample for an error
    source; see ``simulation.impactor.image_draws``)."""

    measurement: Float[Array, "2"]  # LOS angle noise (out-of-plane angle: 0 when planar)


def draw_rows(planar: bool) -> int:
    """Normals per image: planar runs draw only the in-plane measurement angle."""
    return 1 if planar else 2


def pointing_draws(key: PRNGKeyArray) -> Float[Array, "n 2"]:
    """The run's table of ignition pointing normals, ``N_IGNITION_DRAWS`` rows (the second
    column unused when planar)."""
    return stream_normal(key, _IGNITIONS, (N_IGNITION_DRAWS, 2))


def block_draws(key: PRNGKeyArray, block, planar: bool) -> Float[Array, "rows block"]:
    """The normals of images ``block * DRAW_BLOCK + j``, j < DRAW_BLOCK: column j, rows as
    :func:`image_draws_of` reads them (single precision)."""
    shape = (draw_rows(planar), DRAW_BLOCK)
    return jax.random.normal(stream_key(key, _IMAGES, block), shape, jnp.float32)


def image_draws_of(column: tuple, planar: bool) -> ImageDraws:
    """The :class:`ImageDraws` of one column of :func:`block_draws` (float64)."""
    w = [c.astype(jnp.float64) for c in column]
    if planar:
        return ImageDraws(jnp.stack([w[0], jnp.zeros_like(w[0])]))
    return ImageDraws(jnp.stack(w))


def _initial_nav(sim: PNSimulation, key):
    err = sim.errors
    mask = jnp.array([1.0, 1.0, 0.0]) if sim.planar else jnp.ones(3)
    know_pos = mask * err.knowledge_position_m * stream_normal(key, _KNOW_POS)
    know_vel = mask * err.knowledge_velocity_mps * stream_normal(key, _KNOW_VEL)
    frame = sim.los_frame0
    y0 = sim.y0
    x_hat = jnp.concatenate([y0.r + frame.T @ know_pos, y0.v + frame.T @ know_vel])
    sig_p = jnp.maximum(err.knowledge_position_m, 1.0)  # a floor keeps P positive definite
    sig_v = jnp.maximum(err.knowledge_velocity_mps, 1e-6)
    p_pos = frame.T @ jnp.diag(sig_p**2) @ frame
    p0 = jax.scipy.linalg.block_diag(p_pos, sig_v**2 * jnp.eye(3))
    return NavEstimate(x_hat, p0), know_pos, know_vel


def _control_step(
    sim: PNSimulation, law: AugmentedPNGuidance, pointing_table, record, carry: _Carry, t
):
    """One guidance step: APN command -> Schmitt trigger -> pulse -> truth step
    (``drift_kick_drift_step``) -> EKF mean."""
    ctx, err = sim.context, sim.errors
    dt = ctx.dt_s
    perfect = sim.nav_model == "perfect"
    truth = carry.truth
    r_hat, v_hat = (truth.r, truth.v) if perfect else (carry.r_hat, carry.v_hat)
    navsol = PNNavigation(r_hat, v_hat, truth.r_target)

    def law_and_gravity(state, nav):
        # The filter's modelled gravity at the estimate is the law's A_r (eq. 10) before its
        # projection: computed in the same branch, XLA evaluates it once for both.
        command, state = law.step(state, nav, t, ctx)
        g = None if perfect else ctx.dynamics.relative_gravity(nav.r_target, nav.r)
        if not record:  # the command and N are diagnostics of the trace only
            state = state._replace(command_mps2=jnp.zeros(3), coefficient=jnp.zeros(()))
        return command, state, g

    # Once per step, not once per consumer loop (see _numerics.computed_once).
    command, law_state, g = computed_once(law_and_gravity, t, carry.law_state, navsol)
    on = law_state.engine_on
    ignition = (on > 0.5) & (carry.on_prev <= 0.5)
    fresh = err.attitude_rad * pointing_table[carry.ignitions % N_IGNITION_DRAWS]
    pointing = jnp.where(ignition, fresh, carry.pointing_error)

    def engine_and_truth(truth, d, throttle, pointing):
        if sim.planar:  # rotate within the orbit plane about its normal
            tilted = d + pointing[0] * cross3(ctx.reference_normal, d)
            direction = tilted / norm3(tilted)
        else:
            direction = perturb_direction(d, pointing)
        thrust = throttle * sim.engine.thrust_n * direction
        flow = throttle * sim.engine.mass_flow(1.0)
        return direction, thrust, drift_kick_drift_step(sim.dynamics, truth, thrust, flow, dt)

    direction, thrust, new_truth = computed_once(
        engine_and_truth, t, truth, command.direction, command.throttle, pointing
    )
    dv = thrust * (dt / (0.5 * (truth.m + new_truth.m)))
    if not perfect:
        # Executed Δv (perfect accelerometer) plus the modelled gravity over the step,
        # straight-line mean propagation (navigation.ekf.propagate_state).
        dv_nav = dv + g * dt
        r_hat, v_hat = r_hat + v_hat * dt + dv_nav * (0.5 * dt), v_hat + dv_nav
    fired = on > 0.5
    # A firing is one pulse train of one thruster direction: reversing the thrust (the
    # opposite thrusters) while the trigger stays on starts a new firing.
    reversal = fired & (carry.on_prev > 0.5) & (dot3(direction, carry.direction_prev) < 0)
    ign = ignition.astype(jnp.int32)
    new = carry._replace(
        truth=new_truth,
        r_hat=r_hat,
        v_hat=v_hat,
        law_state=law_state,
        on_prev=on,
        direction_prev=direction,
        pointing_error=pointing,
        dv_mps=carry.dv_mps + safe_norm(dv),
        firings=carry.firings + (ignition | reversal).astype(jnp.int32),
        ignitions=carry.ignitions + ign,
        pulses=carry.pulses + fired.astype(jnp.int32),
        last_firing_s=jnp.where(fired, t, carry.last_firing_s),
    )
    rec = None
    if record:
        r_m = truth.r
        rec = PNRecord(t, on, law_state.command_mps2, law_state.coefficient, norm3(r_m), r_m)
    return new, rec


def take_image(
    sim: PNSimulation,
    r_hat: Vector3,
    v_hat: Vector3,
    p: PackedCovariance,
    r_true: Vector3,
    w: Float[Array, "2"],
    key: PRNGKeyArray,
):
    """One LOS measurement and the gain of its EKF update: the camera points at the estimated
    target direction (x_c = h x boresight lies in the orbit plane), the attitude error is white
    angle noise of the front end (``sim.measurement``) and the filter's measurement noise.
    ``w``: the image's two measurement normals; ``key``: for front ends that draw more.

    The update is ``navigation.ekf.ekf_update`` of ``predict_los`` in packed, sequential form
    (``navigation.packed_ekf``); a planar run takes the in-plane angle only (the out-of-plane
    one is exact and would change only out-of-plane entries, see ``packed_ekf.los_update``).
    Returns the :class:`~gnc_jax.navigation.packed_ekf.LOSGain` (zero for a rejected image);
    the caller updates the covariance (``apply_gain``, fused with the propagation).
    """
    # The camera's axes as three row vectors, each product written per row: the stacked
    # matrix is built only for the front end's exposure (read row-wise it is never stored).
    rows = camera_axes(-r_hat, sim.context.reference_normal)
    c_cam = jnp.stack(rows)
    r_var = jnp.maximum(sim.errors.attitude_rad, 1e-9) ** 2
    h_r, predicted = predict_los_packed(rows, r_hat, p, r_var)
    nav = NavEstimate(jnp.concatenate([r_hat, v_hat]), unpack(p))
    meas = sim.measurement(Exposure(-r_true, c_cam, c_cam), nav, predicted, w, key)
    angles = 1 if sim.planar else 2
    innovation = [meas.z[a] - predicted.z[a] for a in range(2)]
    return los_gain(r_hat, v_hat, p, h_r, innovation, r_var, angles, meas.valid)


def _image_step(
    sim: PNSimulation, law: AugmentedPNGuidance, key, pointing_table, record, carry, inputs
):
    """One measurement interval: LOS image -> EKF update -> guidance steps -> covariance.

    ``inputs``: the image index and its column of :func:`block_draws` (one array per row)."""
    i, column = inputs
    dt = sim.context.dt_s
    perfect = sim.nav_model == "perfect"
    image_dt = dt * sim.steps_per_image
    t = i * image_dt
    w = image_draws_of(column, sim.planar)
    if not perfect:
        # The gain once into memory; the covariance update then reads it in one elementwise
        # pass with the propagation (P is not read by the guidance steps in between). The
        # front end's key is derived inside the fenced branch, where XLA drops it when the
        # front end draws nothing (derived outside, its two threefry hashes ran at every
        # image: 15 ns of a 190 ns guidance step).
        gain = computed_once(  # live: the float time (an integer ``i == i`` folds to true)
            lambda *a: take_image(sim, *a, stream_key(key, _FRONT_END, i)),
            t,
            carry.r_hat,
            carry.v_hat,
            carry.p,
            carry.truth.r,
            w.measurement,
        )
        p = propagate_packed(apply_gain(carry.p, gain.terms), image_dt, sim.process_noise_m2s3)
        carry = carry._replace(r_hat=gain.r, v_hat=gain.v, p=p)
    step = functools.partial(_control_step, sim, law, pointing_table, record)
    if sim.steps_per_image == 1:  # one step per image: no inner loop (and its carry copies)
        carry, rec = step(carry, jnp.asarray(t, float))
        rec = jax.tree_util.tree_map(lambda x: x[None], rec)
    else:
        carry, rec = jax.lax.scan(step, carry, t + dt * jnp.arange(sim.steps_per_image))
    return carry, rec


def simulate(
    sim: PNSimulation, law: AugmentedPNGuidance, key: PRNGKeyArray, record: bool = False
) -> tuple[PNOutcome, PNRecord | None]:
    """Simulate one closed-loop intercept.

    Args:
        sim: scenario data (:class:`PNSimulation`).
        law: :class:`~gnc_jax.guidance.intercept.apn.AugmentedPNGuidance`.
        key: this run's key, ``jax.random.fold_in(root, run_index)``.
        record: also return the guidance-rate :class:`PNRecord` trace (static).
    """
    nav0, know_pos, know_vel = _initial_nav(sim, key)
    pointing_table = pointing_draws(key)
    z = jnp.zeros(())
    carry0 = _Carry(
        truth=sim.y0,
        r_hat=nav0.r,
        v_hat=nav0.v,
        p=pack(nav0.p, PLANAR if sim.planar else FULL),
        law_state=law.init(None, sim.context),
        on_prev=z,
        direction_prev=jnp.zeros(3),
        pointing_error=jnp.zeros(2),
        dv_mps=z,
        firings=jnp.zeros((), jnp.int32),
        ignitions=jnp.zeros((), jnp.int32),
        pulses=jnp.zeros((), jnp.int32),
        last_firing_s=z,
    )
    image_step = functools.partial(_image_step, sim, law, key, pointing_table, record)

    def block_inputs(b, length):  # the image indices and their normals, one array per row
        w = block_draws(key, b, sim.planar)
        return b * DRAW_BLOCK + jnp.arange(length), tuple(row[:length] for row in w)

    carry, rec = scan_in_blocks(image_step, carry0, sim.n_images, DRAW_BLOCK, block_inputs)
    rec = flatten_trace(rec)  # (images, steps per image) -> guidance steps

    truth = carry.truth
    b, t_rest = coast_to_b_plane(sim.dynamics, truth, sim.c_bi, sim.coast_steps)
    nav_r = truth.r if sim.nav_model == "perfect" else carry.r_hat
    outcome = PNOutcome(
        status=jnp.zeros((), jnp.int32),
        miss_m=safe_norm(b),
        miss_t_m=b[0],
        miss_r_m=b[1],
        dv_mps=carry.dv_mps,
        firings=carry.firings,
        ignitions=carry.ignitions,
        pulses=carry.pulses,
        last_firing_s=carry.last_firing_s,
        fuel_kg=sim.y0.m - truth.m,
        nav_position_error_m=jnp.linalg.norm(nav_r - truth.r),
        knowledge_position_error_m=know_pos,
        knowledge_velocity_error_mps=know_vel,
        silhouette_ratio=safe_norm(b)
        / (
            sim.dynamics.target_radius_m
            * focusing_factor(
                sim.dynamics.mu_target, sim.dynamics.target_radius_m, safe_norm(sim.y0.v)
            )
        ),
    )
    # ``not (t_rest > 0)`` rather than ``t_rest <= 0``: a NaN coast time is a time-out too.
    outcome = with_status(outcome, [(~(t_rest > 0.0), Status.time_out)])
    return outcome, rec


def initial_state(p: InterceptParameters) -> tuple[InterceptState, bool]:
    """Nominal initial truth (SI) of an intercept scenario's parameters, and whether it is
    planar.

    ``bennu-3d``: the target's state from the Table 1 elements (ecliptic J2000, the paper's
    mu_sun), and the Table 2 relative state (impactor minus target) expressed in the target's
    (radial, transverse, orbit-normal) frame: the planar case rotated onto Bennu's orbit.
    """
    a = p.approach
    r_t, v_t = np.asarray(a.target_position_m), np.asarray(a.target_velocity_mps)
    r_rel = np.asarray(a.impactor_position_m) - r_t
    v_rel = np.asarray(a.impactor_velocity_mps) - v_t
    planar = a.geometry == "planar"
    if not planar:
        # The planar frame of Table 2: x radial, y transverse (the target is at perihelion).
        radial, transverse = r_t / np.linalg.norm(r_t), v_t / np.linalg.norm(v_t)
        rel_rtn = np.array([r_rel @ radial, r_rel @ transverse, r_rel[2]])
        vel_rtn = np.array([v_rel @ radial, v_rel @ transverse, v_rel[2]])
        el = OrbitalElements(
            a.semi_major_axis_m,
            a.eccentricity,
            a.inclination_rad,
            a.raan_rad,
            a.arg_perihelion_rad,
            a.true_anomaly_rad,
        )
        r_t, v_t = (np.asarray(x) for x in elements_to_state(el, p.dynamics.mu_sun_m3s2))
        x = r_t / np.linalg.norm(r_t)
        zn = np.cross(r_t, v_t)
        zn = zn / np.linalg.norm(zn)
        y = np.cross(zn, x)
        rot = np.stack([x, y, zn], axis=1)  # RTN -> ecliptic
        r_rel, v_rel = rot @ rel_rtn, rot @ vel_rtn
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    y0 = InterceptState(f(r_t), f(v_t), f(r_rel), f(v_rel), p.spacecraft.mass_kg)
    return y0, planar


class LoopSizes(NamedTuple):
    """The loop lengths of one run, shared by :func:`build` and the cost model
    (:meth:`InterceptSystem.steps_per_run`)."""

    cutoff_time_s: float  # guidance stops here: the straight-line time of flight - coast_s
    n_images: float  # LOS images (measurement intervals) before the cutoff
    steps_per_image: float  # guidance steps per image


def loop_sizes(p: InterceptParameters, y0: InterceptState) -> LoopSizes:
    """The loop lengths of a scenario with parameters ``p`` and initial truth ``y0``; whole
    numbers (ints) unless they would not fit in one, so that a runaway scenario still gets a
    (refusable) cost estimate."""
    r0, v0 = np.asarray(y0.r), np.asarray(y0.v)
    tof = float(-(r0 @ v0) / (v0 @ v0))
    t_cut = tof - p.guidance.coast_s
    image_dt = p.navigation.image_interval_s
    images, per_image = t_cut / image_dt, image_dt / p.guidance.dt_s
    if images < 1e15 and per_image < 1e15:
        images, per_image = math.ceil(images - 1e-9), round(per_image)
    return LoopSizes(t_cut, images, per_image)


def build(scenario) -> PNSimulation:
    """Simulation data of a validated intercept :class:`Scenario` (SI units, from
    :func:`gnc_jax.systems.intercept.params.parameters`); the law is built by the system from
    ``[guidance.apn]`` (``systems.intercept``)."""
    p = parameters(scenario.config)
    dy, sc, g, nv = p.dynamics, p.spacecraft, p.guidance, p.navigation
    f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
    y0, planar = initial_state(p)
    h = jnp.array([0.0, 0.0, 1.0])  # ecliptic / paper-plane normal: the B-plane reference
    c_bi = b_plane_frame(y0.v, h)
    rho = -np.asarray(y0.r)
    u = rho / np.linalg.norm(rho)
    cross = np.cross(np.asarray(h), u)
    cross = cross / np.linalg.norm(cross)
    los_frame0 = f(np.stack([u, cross, np.cross(u, cross)]))
    sizes = loop_sizes(p, y0)
    dynamics = InterceptDynamics(dy.mu_sun_m3s2, dy.mu_target_m3s2, dy.target_radius_m)
    engine = Engine(sc.thrust_n, sc.isp_s)
    context = PNGuidanceContext(
        range0_m=f(np.linalg.norm(np.asarray(y0.r))),
        cutoff_time_s=f(sizes.cutoff_time_s),
        pulse_fraction=sc.pulse_width_s / g.dt_s,
        dynamics=dynamics,
        reference_normal=h,
        dt_s=g.dt_s,
    )
    return PNSimulation(
        y0=y0,
        context=context,
        dynamics=dynamics,
        engine=engine,
        errors=p.errors,
        process_noise_m2s3=nv.process_noise_m2s3,
        c_bi=c_bi,
        los_frame0=los_frame0,
        planar=planar,
        nav_model=nv.model,
        n_images=int(sizes.n_images),
        steps_per_image=int(sizes.steps_per_image),
        coast_steps=g.coast_steps,
        measurement=GaussianLOSMeasurement(p.errors.attitude_rad, planar=planar),
    )


__all__ = [
    "LoopSizes",
    "PNErrors",
    "PNOutcome",
    "PNRecord",
    "PNSimulation",
    "build",
    "initial_state",
    "loop_sizes",
    "simulate",
]
