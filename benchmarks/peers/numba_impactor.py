"""The hand-written numba peer of gnc_jax's flagship closed loop, ``deep-impact-los``.

    python benchmarks/peers/numba_impactor.py [--quick] [--sizes 2000 10000] [--repeats 3]

A scalar transcription of `gnc_jax.systems.impactor.simulation.simulate` with the LOS
switching-curve law, as an expert numba user would write it: ``@njit(parallel=True)`` with
``prange`` over runs, scalar code inside (vectors as three floats, the 6x6 covariance in one array
per run), nothing allocated per step, and branches where the work is conditional (the engine fires
in about 0.5 % of the control steps). Same truth (RK4 of the target's point-mass gravity + solar
tide, thrust and mass flow held over the step), same camera and Gaussian LOS front end, same EKF
(closed-form LOS Jacobian, the two angles' scalar updates written out, straight-line covariance
growth, attitude-error rotations from power series), same law (error ellipse at each image,
switching curves of k1 and k2 sigma_B with the one-step floor, Schmitt trigger, zero-effort-miss
thrust direction), same error sources and the same outcome (coast to the B-plane, miss, Δv, firings,
fuel, status ``propellant``). Every number comes from ``gj.build(scenario)``; nothing is copied by
hand.

Two ways to feed it random numbers:

* **fed**: the standard normals gnc_jax draws,
  `gnc_jax.systems.impactor.draws.run_draws` of each run's key, stacked over runs: the
  outcomes equal gnc_jax's run for run (``tests/test_peer_numba.py``);
* **own**: the kernel draws its own normals with numba's ``np.random.standard_normal``
  (per-thread Mersenne twister, seeded ``seed + i`` for run ``i``), only what is used: 15 per run
  (delivery, knowledge, attitude and accelerometer biases), 8 per image (image processing,
  attitude control, attitude knowledge), 4 per ignition (burn magnitude, pointing) and 6 per
  image interval in which the engine fired (the accelerometer's white noise integrated over the
  interval). Same distributions as gnc_jax's layout, in float64 (gnc_jax draws its per-image
  normals in single precision); gnc_jax's ignition and accelerometer draws come from a per-run
  table with a row per image interval in which the engine fires (its first ignition, its
  later ones, the accelerometer noise), here every ignition draws afresh.

The benchmark times both against gnc_jax's ``run_study`` and its sharded batch function (as
``benchmarks/impactor.py`` times it) in the same process, and profiles the kernel by switching
its image updates and its control steps off.
"""

# numba's per-thread generator is reached through the legacy np.random functions (a numpy
# Generator can only be passed in, one state shared by every thread).
# ruff: noqa: NPY002

import argparse
import functools
import math
import os
import pathlib
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import gnc_jax as gj  # first: float64 and one XLA device per core
from gnc_jax.systems.impactor import draws as _layout

try:
    import numba
    from numba import njit, prange
except ImportError:  # the module still imports (the suite reports the peer as missing)
    numba = None

    def njit(*args, **kwargs):
        return (lambda f: f) if not args or not callable(args[0]) else args[0]

    prange = range

SCENARIO = "deep-impact-los"
MODULE = "benchmarks.peers.numba_impactor"  # the name numba's on-disk cache records
ROOT = pathlib.Path(__file__).resolve().parents[2]
# IEEE semantics as in JAX (x / 0 is inf, not ZeroDivisionError) and no reassociation. numba's
# cache stores the module's name and re-imports it on load: a copy loaded under a name that
# cannot be imported (importlib from a path, not in sys.modules) compiles without the cache.
_JIT = dict(cache=__name__ in sys.modules, fastmath=False, error_model="numpy")

# Layout of the parameter vector handed to the kernel (indices are compile-time constants).
R0, V0, SUN = 0, 3, 6  # nominal initial position (m), velocity (m/s); unit Sun direction
MASS, PROPELLANT, THRUST, FLOW = 9, 10, 11, 12  # kg, kg, N, kg/s at full throttle (truth)
MU, TIDE = 13, 14  # target GM (m^3/s^2), solar tide rate^2 (1/s^2)
DT, IMAGE_DT, RETARGET, CUTOFF = 15, 16, 17, 18  # s (mission time)
AIM_INITIAL, AIM_FINAL = 19, 21  # (B_T, B_R), m
CTX_THRUST, CTX_MASS, K1, K2 = 23, 24, 25, 26  # the law's engine and mass; its gains
SIG_DELIVERY, SIG_KNOW_POS, SIG_KNOW_VEL = 27, 28, 31  # m (per axis), m along S T R, m/s
SIG_IMAGE, SIG_ATT_CONTROL, SIG_ATT_BIAS, SIG_ATT_NOISE = 32, 33, 34, 35  # rad
SIG_ACC_BIAS, SIG_ACC_NOISE, SIG_BURN = 36, 37, 38  # m/s^2, m/s^2, fraction
SIG_FRONT_END, PROCESS_NOISE = 39, 40  # rad (Gaussian LOS front end), m^2/s^3
N_PARAMS = 41

# Per-run outcome columns.
OUT_FIELDS = (
    "status",
    "miss_m",
    "miss_t_m",
    "miss_r_m",
    "b_t_m",
    "b_r_m",
    "dv_mps",
    "firings",
    "burn_time_s",
    "fuel_kg",
    "nav_position_error_m",
    "nav_sigma_b_m",
    "los_error_rms_urad",
)
N_OUT = len(OUT_FIELDS)
N_FIXED = 15  # per-run normals: delivery, knowledge position, velocity, attitude/accel biases
# gnc_jax's layout: normals per image, and the per-run table of burn draws (rows, normals per
# row), taken from gnc_jax so that the fed layout cannot drift from it
IMAGE_DRAWS = _layout.IMAGE_DRAWS
N_BURN_INTERVALS, BURN_DRAWS = _layout.N_BURN_INTERVALS, _layout.BURN_DRAWS
STATUS_OK, STATUS_NAN, STATUS_PROPELLANT = (
    int(gj.Status.ok),
    int(gj.Status.nan),
    int(gj.Status.propellant),
)


# --------------------------------------------------------------------------------------------
# Problem data: everything from gj.build, as numbers and arrays


def problem(scenario):
    """``(prm, c_bi, p0, n_images, steps_per_image, coast_steps)`` of an impactor scenario with
    the LOS law and the Gaussian LOS front end, from ``gj.build``; ``p0`` is the filter's
    initial covariance (the same for every run: it depends on the nominal state only)."""
    from gnc_jax.guidance.impactor.los import LOSSwitchingCurveGuidance
    from gnc_jax.navigation.measurements.gaussian import GaussianLOSMeasurement

    sim, law = gj.build(scenario)
    if not isinstance(law, LOSSwitchingCurveGuidance) or law.relaxed:
        raise ValueError(f"{scenario.name}: the numba peer transcribes the hard LOS law only")
    if not isinstance(sim.measurement, GaussianLOSMeasurement) or sim.measurement.planar:
        raise ValueError(f"{scenario.name}: the numba peer transcribes the Gaussian LOS front end")
    if float(sim.errors.camera_misalignment_rad) != 0.0:
        raise ValueError(f"{scenario.name}: the numba peer has no camera misalignment")
    f = lambda x: np.asarray(x, dtype=np.float64)  # noqa: E731
    ctx, err, dyn = sim.context, sim.errors, sim.dynamics
    prm = np.zeros(N_PARAMS)
    prm[R0 : R0 + 3] = f(sim.r0_m)
    prm[V0 : V0 + 3] = f(sim.v0_mps)
    prm[SUN : SUN + 3] = f(dyn.sun_direction)
    prm[MASS] = f(sim.mass_kg)
    prm[PROPELLANT] = f(sim.propellant_kg)
    prm[THRUST] = f(sim.engine.thrust_n)
    prm[FLOW] = f(sim.engine.mass_flow(1.0))
    prm[MU] = f(dyn.mu_target)
    prm[TIDE] = f(dyn.tide_rate2)
    prm[DT] = ctx.dt_s
    prm[IMAGE_DT] = ctx.image_interval_s
    prm[RETARGET] = f(ctx.retarget_time_s)
    prm[CUTOFF] = f(ctx.cutoff_time_s)
    prm[AIM_INITIAL : AIM_INITIAL + 2] = f(ctx.aim_initial_m)
    prm[AIM_FINAL : AIM_FINAL + 2] = f(ctx.aim_final_m)
    prm[CTX_THRUST] = f(ctx.engine.thrust_n)
    prm[CTX_MASS] = f(ctx.mass_kg)
    prm[K1] = f(law.k1)
    prm[K2] = f(law.k2)
    prm[SIG_DELIVERY] = f(err.delivery_position_m)
    prm[SIG_KNOW_POS : SIG_KNOW_POS + 3] = f(err.knowledge_position_m)
    prm[SIG_KNOW_VEL] = f(err.knowledge_velocity_mps)
    prm[SIG_IMAGE] = f(err.image_processing_rad)
    prm[SIG_ATT_CONTROL] = f(err.attitude_control_rad)
    prm[SIG_ATT_BIAS] = f(err.attitude_bias_rad)
    prm[SIG_ATT_NOISE] = f(err.attitude_noise_rad)
    prm[SIG_ACC_BIAS] = f(err.accel_bias_mps2)
    prm[SIG_ACC_NOISE] = f(err.accel_noise_mps2)
    prm[SIG_BURN] = f(err.burn_magnitude_frac)
    prm[SIG_FRONT_END] = f(sim.measurement.sigma_rad)
    prm[PROCESS_NOISE] = f(sim.process_noise_m2s3)
    c_bi = np.ascontiguousarray(f(ctx.c_bi))
    # Initial covariance: knowledge errors along S, T, R rotated to inertial, velocity knowledge,
    # and (considered) the trajectory rotation an attitude bias cannot be told from.
    kp, kv = f(err.knowledge_position_m), float(f(err.knowledge_velocity_mps))
    p0 = np.zeros((6, 6))
    p0[:3, :3] = (c_bi.T * kp**2) @ c_bi
    p0[3:, 3:] = kv**2 * np.eye(3)

    def cross_matrix(a):
        return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])

    g = -np.concatenate([cross_matrix(prm[R0 : R0 + 3]), cross_matrix(prm[V0 : V0 + 3])])
    p0 += float(f(sim.consider_attitude_bias)) * float(f(err.attitude_bias_rad)) ** 2 * (g @ g.T)
    return prm, c_bi, p0, sim.n_images, sim.steps_per_image, sim.coast_steps


# --------------------------------------------------------------------------------------------
# The kernel: scalar code, one run per call, prange over runs


@njit(**_JIT)
def _gravity(mu, tide, s0, s1, s2, x, y, z):
    """Point-mass gravity of the target + linearised solar tide at (x, y, z), m/s^2.

    A term whose constant is zero is skipped: it would add exact zeros (the same bits)."""
    g0 = g1 = g2 = 0.0
    if mu != 0.0:
        r2 = x * x + y * y + z * z
        if r2 != 0.0:  # at the centre itself the point-mass term is 0 (gnc_jax's convention)
            den = r2 * np.sqrt(r2)
            g0, g1, g2 = -mu * x / den, -mu * y / den, -mu * z / den
    if tide != 0.0:
        d = 3.0 * (x * s0 + y * s1 + z * s2)
        g0, g1, g2 = g0 + tide * (d * s0 - x), g1 + tide * (d * s1 - y), g2 + tide * (d * s2 - z)
    return g0, g1, g2


@njit(**_JIT)
def _rk4(mu, tide, s0, s1, s2, x, y, z, vx, vy, vz, m, fx, fy, fz, flow, dt):
    """One classical RK4 step of (r, v, m) with the thrust (N) and mass flow (kg/s) held."""
    h = 0.5 * dt
    g0, g1, g2 = _gravity(mu, tide, s0, s1, s2, x, y, z)
    k1x, k1y, k1z = vx, vy, vz
    k1u, k1v, k1w = g0 + fx / m, g1 + fy / m, g2 + fz / m
    m2 = m + h * -flow
    x2, y2, z2 = x + h * k1x, y + h * k1y, z + h * k1z
    g0, g1, g2 = _gravity(mu, tide, s0, s1, s2, x2, y2, z2)
    k2x, k2y, k2z = vx + h * k1u, vy + h * k1v, vz + h * k1w
    k2u, k2v, k2w = g0 + fx / m2, g1 + fy / m2, g2 + fz / m2
    m3 = m + h * -flow
    x3, y3, z3 = x + h * k2x, y + h * k2y, z + h * k2z
    g0, g1, g2 = _gravity(mu, tide, s0, s1, s2, x3, y3, z3)
    k3x, k3y, k3z = vx + h * k2u, vy + h * k2v, vz + h * k2w
    k3u, k3v, k3w = g0 + fx / m3, g1 + fy / m3, g2 + fz / m3
    m4 = m + dt * -flow
    x4, y4, z4 = x + dt * k3x, y + dt * k3y, z + dt * k3z
    g0, g1, g2 = _gravity(mu, tide, s0, s1, s2, x4, y4, z4)
    k4x, k4y, k4z = vx + dt * k3u, vy + dt * k3v, vz + dt * k3w
    k4u, k4v, k4w = g0 + fx / m4, g1 + fy / m4, g2 + fz / m4
    c = dt / 6.0
    return (
        x + c * (k1x + 2.0 * k2x + 2.0 * k3x + k4x),
        y + c * (k1y + 2.0 * k2y + 2.0 * k3y + k4y),
        z + c * (k1z + 2.0 * k2z + 2.0 * k3z + k4z),
        vx + c * (k1u + 2.0 * k2u + 2.0 * k3u + k4u),
        vy + c * (k1v + 2.0 * k2v + 2.0 * k3v + k4v),
        vz + c * (k1w + 2.0 * k2w + 2.0 * k3w + k4w),
        m + c * (-flow + 2.0 * -flow + 2.0 * -flow + -flow),
    )


@njit(**_JIT)
def _rk4_coast(mu, tide, s0, s1, s2, x, y, z, vx, vy, vz, dt):
    """:func:`_rk4` without thrust or mass flow (the same bits: those terms add zeros)."""
    h = 0.5 * dt
    k1u, k1v, k1w = _gravity(mu, tide, s0, s1, s2, x, y, z)
    k2x, k2y, k2z = vx + h * k1u, vy + h * k1v, vz + h * k1w
    k2u, k2v, k2w = _gravity(mu, tide, s0, s1, s2, x + h * vx, y + h * vy, z + h * vz)
    k3x, k3y, k3z = vx + h * k2u, vy + h * k2v, vz + h * k2w
    k3u, k3v, k3w = _gravity(mu, tide, s0, s1, s2, x + h * k2x, y + h * k2y, z + h * k2z)
    k4x, k4y, k4z = vx + dt * k3u, vy + dt * k3v, vz + dt * k3w
    k4u, k4v, k4w = _gravity(mu, tide, s0, s1, s2, x + dt * k3x, y + dt * k3y, z + dt * k3z)
    c = dt / 6.0
    return (
        x + c * (vx + 2.0 * k2x + 2.0 * k3x + k4x),
        y + c * (vy + 2.0 * k2y + 2.0 * k3y + k4y),
        z + c * (vz + 2.0 * k2z + 2.0 * k3z + k4z),
        vx + c * (k1u + 2.0 * k2u + 2.0 * k3u + k4u),
        vy + c * (k1v + 2.0 * k2v + 2.0 * k3v + k4v),
        vz + c * (k1w + 2.0 * k2w + 2.0 * k3w + k4w),
    )


_SINC = tuple((-1) ** n / math.factorial(2 * n + 1) for n in range(16))
_COSC = tuple((-1) ** n / math.factorial(2 * n + 2) for n in range(16))


@njit(**_JIT)
def _series(c, x):
    acc = c[15]
    for n in range(14, -1, -1):
        acc = acc * x + c[n]
    return acc


@njit(**_JIT)
def _small_rotation(t0, t1, t2, out):
    """Rotation matrix of the rotation vector (t0, t1, t2) into ``out`` (3x3):
    cos(a) I + (sin(a)/a) [t x] + ((1 - cos a)/a^2) t t^T with both ratios as 16-term power
    series in a^2 (``navigation.camera.small_rotation_entries``)."""
    a2 = t0 * t0 + t1 * t1 + t2 * t2
    s = _series(_SINC, a2)
    c = _series(_COSC, a2)
    d = 1.0 - c * a2
    s0, s1, s2 = s * t0, s * t1, s * t2
    out[0, 0], out[0, 1], out[0, 2] = d + c * t0 * t0, c * t0 * t1 - s2, c * t0 * t2 + s1
    out[1, 0], out[1, 1], out[1, 2] = c * t1 * t0 + s2, d + c * t1 * t1, c * t1 * t2 - s0
    out[2, 0], out[2, 1], out[2, 2] = c * t2 * t0 - s1, c * t2 * t1 + s0, d + c * t2 * t2


@njit(**_JIT)
def _matmul3(a, b, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@njit(**_JIT)
def _sigma_b(p, t_go, c_bi):
    """sqrt(sT^2 + sR^2) of the position covariance mapped to impact along a straight line
    (seed 000 eqs. 8-11), m."""
    d = 0.0
    for a in (1, 2):
        for i in range(3):
            for j in range(3):
                prr = p[i, j] + t_go * (p[i, j + 3] + p[i + 3, j]) + t_go * t_go * p[i + 3, j + 3]
                d += c_bi[a, i] * prr * c_bi[a, j]
    return np.sqrt(d)


@njit(**_JIT)
def _b_plane_point(c_bi, bt, br):
    """Inertial position of the B-plane point (B_T, B_R), m."""
    return (
        bt * c_bi[1, 0] + br * c_bi[2, 0],
        bt * c_bi[1, 1] + br * c_bi[2, 1],
        bt * c_bi[1, 2] + br * c_bi[2, 2],
    )


@njit(**_JIT)
def _aim_point(prm, c_bi, t):
    """Inertial position of the aim point at mission time ``t``, m."""
    a = AIM_FINAL if t >= prm[RETARGET] else AIM_INITIAL
    return _b_plane_point(c_bi, prm[a], prm[a + 1])


@njit(**_JIT)
def _plan(prm, c_bi, p, t, rh0, rh1, rh2, vh0, vh1, vh2):
    """The law's plan: sigma_B of the estimate, t_go = |aim - r_hat| / |v_hat| (eq. 9)."""
    a0, a1, a2 = _aim_point(prm, c_bi, t)
    q0, q1, q2 = a0 - rh0, a1 - rh1, a2 - rh2
    t_go = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2) / np.sqrt(vh0 * vh0 + vh1 * vh1 + vh2 * vh2)
    return _sigma_b(p, t_go, c_bi)


@njit(**_JIT)
def _switching_curve(rho, rdot, limit):
    """LOS rate at which the unforced miss equals ``limit`` (seed 000 eq. 20), rad/s."""
    rho2 = rho * rho
    arg = rho2 * rho2 - limit * limit * rho2
    if arg > 0.0:
        return -limit * rdot / np.sqrt(arg)
    return np.inf


@njit(**_JIT)
def _run(
    prm,
    c_bi,
    p0,
    n_images,
    steps,
    coast_steps,
    own,
    fixed,
    burns,
    images,
    do_images,
    do_steps,
    out,
):
    """One closed-loop run into ``out`` (OUT_FIELDS). ``own``: draw the normals here (numba's
    per-thread generator, seeded by the caller); else read them from ``fixed`` (15),
    ``burns`` (64 x 14) and ``images`` (n_images x 8), gnc_jax's layout. ``do_images`` /
    ``do_steps``: the profile's switches (both True for a real run)."""
    dt, image_dt = prm[DT], prm[IMAGE_DT]
    mu, tide, s0, s1, s2 = prm[MU], prm[TIDE], prm[SUN], prm[SUN + 1], prm[SUN + 2]
    thrust_n, flow_max, cutoff = prm[THRUST], prm[FLOW], prm[CUTOFF]
    k1, k2 = prm[K1], prm[K2]
    resolution_rate = 0.5 * prm[CTX_THRUST] / prm[CTX_MASS] * dt  # miss per s of t_go per step
    sig_ctrl, sig_noise, sig_burn = prm[SIG_ATT_CONTROL], prm[SIG_ATT_NOISE], prm[SIG_BURN]
    r_meas = prm[SIG_IMAGE] * prm[SIG_IMAGE] + sig_noise * sig_noise
    sig_front = prm[SIG_FRONT_END]
    acc_noise, acc_sig = prm[SIG_ACC_NOISE], prm[SIG_ACC_BIAS]
    sigma_dv = acc_noise * dt
    fb0, fb1, fb2 = c_bi[1, 0], c_bi[1, 1], c_bi[1, 2]  # thrust direction when ZEM = 0
    retarget = prm[RETARGET]
    ai0, ai1, ai2 = _b_plane_point(c_bi, prm[AIM_INITIAL], prm[AIM_INITIAL + 1])  # aim points
    af0, af1, af2 = _b_plane_point(c_bi, prm[AIM_FINAL], prm[AIM_FINAL + 1])
    up0, up1, up2 = c_bi[2, 0], c_bi[2, 1], c_bi[2, 2]  # camera roll reference

    # Per-run draws and initial conditions.
    w = np.empty(18)  # [0:15] per run, then [0:8] per image, [8:12] ignition, [12:18] accel
    if own:
        for j in range(N_FIXED):
            w[j] = np.random.standard_normal()
    else:
        for j in range(N_FIXED):
            w[j] = fixed[j]
    sd = prm[SIG_DELIVERY]
    x, y, z = prm[R0] + sd * w[0], prm[R0 + 1] + sd * w[1], prm[R0 + 2] + sd * w[2]
    vx, vy, vz, m = prm[V0], prm[V0 + 1], prm[V0 + 2], prm[MASS]
    kp0 = prm[SIG_KNOW_POS] * w[3]
    kp1 = prm[SIG_KNOW_POS + 1] * w[4]
    kp2 = prm[SIG_KNOW_POS + 2] * w[5]
    rh0 = x + (c_bi[0, 0] * kp0 + c_bi[1, 0] * kp1 + c_bi[2, 0] * kp2)
    rh1 = y + (c_bi[0, 1] * kp0 + c_bi[1, 1] * kp1 + c_bi[2, 1] * kp2)
    rh2 = z + (c_bi[0, 2] * kp0 + c_bi[1, 2] * kp1 + c_bi[2, 2] * kp2)
    skv = prm[SIG_KNOW_VEL]
    vh0, vh1, vh2 = vx + skv * w[6], vy + skv * w[7], vz + skv * w[8]
    ab0, ab1, ab2 = prm[SIG_ATT_BIAS] * w[9], prm[SIG_ATT_BIAS] * w[10], prm[SIG_ATT_BIAS] * w[11]
    ba0, ba1, ba2 = acc_sig * w[12], acc_sig * w[13], acc_sig * w[14]
    p = p0.copy()
    pn = np.empty((6, 6))
    c_cmd, rot = np.empty((3, 3)), np.empty((3, 3))  # commanded attitude, a small rotation
    c_true, c_est = np.empty((3, 3)), np.empty((3, 3))  # true and believed camera attitude
    pht, gain = np.empty((6, 2)), np.empty((6, 2))  # u = P h^T and w = u / s per angle

    engine_on = 0.0
    sigma_b = _plan(prm, c_bi, p, 0.0, rh0, rh1, rh2, vh0, vh1, vh2)
    throttle_prev = 0.0
    e_mag = e_p0 = e_p1 = e_p2 = 0.0  # execution error of the current firing (normals)
    burn_intervals = 0
    dv_total = burn_time = los_error_sq = 0.0
    firings = images_used = 0
    q0 = q1 = q2 = qv = vv = 0.0  # the law's rho, rho . rho_dot, |v_hat|^2 (thrust direction)

    for i in range(n_images):
        t_img = i * image_dt
        if own:
            for j in range(8):
                w[j] = np.random.standard_normal()
        else:
            for j in range(IMAGE_DRAWS):
                w[j] = images[i, j]
        if do_images:
            # Camera pointed at the estimated target direction (roll from the B-plane R axis).
            b0, b1, b2 = -rh0, -rh1, -rh2
            nb = np.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
            zc0, zc1, zc2 = b0 / nb, b1 / nb, b2 / nb
            xc0, xc1, xc2 = up1 * zc2 - up2 * zc1, up2 * zc0 - up0 * zc2, up0 * zc1 - up1 * zc0
            nx = np.sqrt(xc0 * xc0 + xc1 * xc1 + xc2 * xc2)
            xc0, xc1, xc2 = xc0 / nx, xc1 / nx, xc2 / nx
            c_cmd[0, 0], c_cmd[0, 1], c_cmd[0, 2] = xc0, xc1, xc2
            c_cmd[1, 0] = zc1 * xc2 - zc2 * xc1
            c_cmd[1, 1] = zc2 * xc0 - zc0 * xc2
            c_cmd[1, 2] = zc0 * xc1 - zc1 * xc0
            c_cmd[2, 0], c_cmd[2, 1], c_cmd[2, 2] = zc0, zc1, zc2
            # True attitude: control error; believed attitude: bias + knowledge noise.
            _small_rotation(sig_ctrl * w[2], sig_ctrl * w[3], sig_ctrl * w[4], rot)
            _matmul3(rot, c_cmd, c_true)
            _small_rotation(
                ab0 + sig_noise * w[5], ab1 + sig_noise * w[6], ab2 + sig_noise * w[7], rot
            )
            _matmul3(rot, c_true, c_est)
            # Predicted angles and the LOS Jacobian (position columns only).
            e0 = -(c_est[0, 0] * rh0 + c_est[0, 1] * rh1 + c_est[0, 2] * rh2)
            e1 = -(c_est[1, 0] * rh0 + c_est[1, 1] * rh1 + c_est[1, 2] * rh2)
            e2 = -(c_est[2, 0] * rh0 + c_est[2, 1] * rh1 + c_est[2, 2] * rh2)
            inv = 1.0 / e2
            zp0, zp1 = e0 * inv, e1 * inv
            h00 = -(c_est[0, 0] - zp0 * c_est[2, 0]) * inv
            h01 = -(c_est[0, 1] - zp0 * c_est[2, 1]) * inv
            h02 = -(c_est[0, 2] - zp0 * c_est[2, 2]) * inv
            h10 = -(c_est[1, 0] - zp1 * c_est[2, 0]) * inv
            h11 = -(c_est[1, 1] - zp1 * c_est[2, 1]) * inv
            h12 = -(c_est[1, 2] - zp1 * c_est[2, 2]) * inv
            # Measurement: true angles in the true camera frame + image-processing noise.
            t0 = -(c_true[0, 0] * x + c_true[0, 1] * y + c_true[0, 2] * z)
            t1 = -(c_true[1, 0] * x + c_true[1, 1] * y + c_true[1, 2] * z)
            t2 = -(c_true[2, 0] * x + c_true[2, 1] * y + c_true[2, 2] * z)
            zt0, zt1 = t0 / t2, t1 / t2
            zm0, zm1 = zt0 + sig_front * w[0], zt1 + sig_front * w[1]
            los_error_sq += (zm0 - zt0) ** 2 + (zm1 - zt1) ** 2
            images_used += 1
            # EKF update as two scalar updates (``navigation.packed_ekf.los_gain``; R = r I):
            # u = P h^T, s = h u + r, x += u nu / s, P -= u u^T / s; the second angle's u
            # and innovation keep the prior's linearisation point (sa, sb: not the Sun's s1, s2).
            for r in range(6):
                pht[r, 0] = p[r, 0] * h00 + p[r, 1] * h01 + p[r, 2] * h02
                pht[r, 1] = p[r, 0] * h10 + p[r, 1] * h11 + p[r, 2] * h12
            sa = pht[0, 0] * h00 + pht[1, 0] * h01 + pht[2, 0] * h02 + r_meas + 1e-200
            g1 = (zm0 - zp0) / sa
            c12 = pht[0, 0] * h10 + pht[1, 0] * h11 + pht[2, 0] * h12
            for r in range(6):
                gain[r, 0] = pht[r, 0] / sa  # w1 = u1 / sa
                pht[r, 1] = pht[r, 1] - gain[r, 0] * c12  # u2
            sb = pht[0, 1] * h10 + pht[1, 1] * h11 + pht[2, 1] * h12 + r_meas + 1e-200
            da, db, dc = pht[0, 0] * g1, pht[1, 0] * g1, pht[2, 0] * g1
            g2 = ((zm1 - zp1) - (h10 * da + h11 * db + h12 * dc)) / sb
            for r in range(6):
                gain[r, 1] = pht[r, 1] / sb
            rh0 += da
            rh1 += db
            rh2 += dc
            vh0 += pht[3, 0] * g1
            vh1 += pht[4, 0] * g1
            vh2 += pht[5, 0] * g1
            rh0 += pht[0, 1] * g2
            rh1 += pht[1, 1] * g2
            rh2 += pht[2, 1] * g2
            vh0 += pht[3, 1] * g2
            vh1 += pht[4, 1] * g2
            vh2 += pht[5, 1] * g2
            for r in range(6):
                for c in range(r, 6):
                    v = p[r, c] - gain[r, 0] * pht[c, 0] - gain[r, 1] * pht[c, 1]
                    p[r, c] = v
                    p[c, r] = v
            sigma_b = _plan(prm, c_bi, p, t_img, rh0, rh1, rh2, vh0, vh1, vh2)

        # Execution draws of this interval's ignitions (fed: gnc_jax's burn-table row).
        row = 0 if own else burn_intervals % N_BURN_INTERVALS
        first_mag, first_p0, first_p1, first_p2 = (
            burns[row, 0], burns[row, 1], burns[row, 2], burns[row, 3]
        )  # fmt: skip
        ignitions_image = 0
        mom_a = mom_b = mom_c = 0.0
        burn_image = 0.0
        if do_steps:
            for k in range(steps):
                t = t_img + dt * k
                throttle = 0.0
                if t < cutoff:
                    if t >= retarget:
                        a0, a1, a2 = af0, af1, af2
                    else:
                        a0, a1, a2 = ai0, ai1, ai2
                    q0, q1, q2 = a0 - rh0, a1 - rh1, a2 - rh2  # rho; rho_dot = -v_hat
                    rr = q0 * q0 + q1 * q1 + q2 * q2
                    rho_n = np.sqrt(rr)
                    qv = -(q0 * vh0 + q1 * vh1 + q2 * vh2)  # rho . rho_dot
                    rdot = qv / rho_n
                    o0 = q1 * vh2 - q2 * vh1  # |rho x rho_dot| / rho^2 = |omega| (eq. 21)
                    o1 = q2 * vh0 - q0 * vh2
                    o2 = q0 * vh1 - q1 * vh0
                    omega = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2) / rr
                    vv = vh0 * vh0 + vh1 * vh1 + vh2 * vh2
                    speed = np.sqrt(vv) if vv > 0.0 else 0.0
                    resolution = resolution_rate * (rho_n / speed)
                    rho_close = max(k2 * sigma_b, resolution)
                    rho_open = max(k1 * sigma_b, rho_close)
                    if omega >= _switching_curve(rho_n, rdot, rho_open):
                        engine_on = 1.0
                    elif omega <= _switching_curve(rho_n, rdot, rho_close):
                        engine_on = 0.0
                    throttle = engine_on
                else:
                    engine_on = 0.0
                if throttle > 0.0:
                    if throttle_prev <= 0.0:  # ignition: this firing's execution error
                        if own:
                            e_mag = np.random.standard_normal()
                            e_p0 = np.random.standard_normal()
                            e_p1 = np.random.standard_normal()
                            e_p2 = np.random.standard_normal()
                        elif ignitions_image == 0:
                            e_mag, e_p0, e_p1, e_p2 = first_mag, first_p0, first_p1, first_p2
                        else:
                            e_mag, e_p0, e_p1, e_p2 = (
                                burns[row, 4],
                                burns[row, 5],
                                burns[row, 6],
                                burns[row, 7],
                            )
                        ignitions_image += 1
                        firings += 1
                    # Thrust along the zero-effort-miss direction, tilted by the pointing error.
                    f = qv / vv  # rho . rho_dot / |rho_dot|^2
                    u0, u1, u2 = q0 + f * vh0, q1 + f * vh1, q2 + f * vh2  # rho - f rho_dot
                    n2 = u0 * u0 + u1 * u1 + u2 * u2
                    if n2 > 1e-30:
                        nu = np.sqrt(n2)
                        u0, u1, u2 = u0 / nu, u1 / nu, u2 / nu
                    else:
                        u0, u1, u2 = fb0, fb1, fb2
                    d0, d1, d2 = sig_ctrl * e_p0, sig_ctrl * e_p1, sig_ctrl * e_p2
                    du = d0 * u0 + d1 * u1 + d2 * u2
                    u0, u1, u2 = u0 + d0 - du * u0, u1 + d1 - du * u1, u2 + d2 - du * u2
                    nu = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
                    mag = throttle * (thrust_n * (1.0 + sig_burn * e_mag))
                    f0, f1, f2 = mag * (u0 / nu), mag * (u1 / nu), mag * (u2 / nu)
                    m_old = m
                    x, y, z, vx, vy, vz, m = _rk4(
                        mu, tide, s0, s1, s2, x, y, z, vx, vy, vz, m, f0, f1, f2,
                        throttle * flow_max, dt,
                    )  # fmt: skip
                    # Accelerometer: the burn's Δv plus the bias (white noise per interval).
                    scale = dt / (0.5 * (m_old + m))
                    dvt0, dvt1, dvt2 = f0 * scale, f1 * scale, f2 * scale
                    tb = throttle * dt
                    dm0, dm1, dm2 = dvt0 + tb * ba0, dvt1 + tb * ba1, dvt2 + tb * ba2
                    rh0 = rh0 + vh0 * dt + dm0 * (0.5 * dt)
                    rh1 = rh1 + vh1 * dt + dm1 * (0.5 * dt)
                    rh2 = rh2 + vh2 * dt + dm2 * (0.5 * dt)
                    vh0, vh1, vh2 = vh0 + dm0, vh1 + dm1, vh2 + dm2
                    th2 = throttle * throttle
                    c_k = dt * (steps - k - 0.5)
                    mom_a += th2
                    mom_b += th2 * c_k
                    mom_c += th2 * c_k * c_k
                    dv_total += np.sqrt(dvt0 * dvt0 + dvt1 * dvt1 + dvt2 * dvt2)
                    burn_time += tb
                    burn_image += tb
                else:  # coasting: truth under gravity alone, estimate along a straight line
                    x, y, z, vx, vy, vz = _rk4_coast(mu, tide, s0, s1, s2, x, y, z, vx, vy, vz, dt)
                    rh0 += vh0 * dt
                    rh1 += vh1 * dt
                    rh2 += vh2 * dt
                throttle_prev = throttle
        if do_images:
            if mom_a > 0.0:  # accelerometer white noise over the interval (accel_noise)
                if own:
                    for j in range(12, 18):
                        w[j] = np.random.standard_normal()
                else:
                    for j in range(12, 18):
                        w[j] = burns[row, j - 4]
                burn_intervals += 1
                sa = np.sqrt(mom_a)
                beta = mom_b / sa
                gamma = np.sqrt(max(mom_c - beta * beta, 0.0))
                sv = sigma_dv * sa
                rh0 += sigma_dv * (beta * w[12] + gamma * w[15])
                rh1 += sigma_dv * (beta * w[13] + gamma * w[16])
                rh2 += sigma_dv * (beta * w[14] + gamma * w[17])
                vh0 += sv * w[12]
                vh1 += sv * w[13]
                vh2 += sv * w[14]
            # Covariance growth over the interval: straight line + process and Δv noise.
            q_dv = acc_noise * acc_noise * dt * burn_image + acc_sig * acc_sig * (
                burn_image * burn_image
            )
            q = prm[PROCESS_NOISE]
            q_rr = q * (image_dt * image_dt * image_dt) / 3.0
            q_rv = q * (image_dt * image_dt) / 2.0
            q_vv = q * image_dt + q_dv
            for r in range(6):
                for c in range(r, 6):
                    if c < 3:
                        v = (
                            p[r, c]
                            + image_dt * (p[r, c + 3] + p[r + 3, c])
                            + image_dt * image_dt * p[r + 3, c + 3]
                        )
                        if r == c:
                            v += q_rr
                    elif r < 3:
                        v = p[r, c] + image_dt * p[r + 3, c]
                        if c == r + 3:
                            v += q_rv
                    else:
                        v = p[r, c]
                        if r == c:
                            v += q_vv
                    pn[r, c] = v
                    pn[c, r] = v
            p, pn = pn, p

    # Coast to the B-plane: RK4 over the straight-line time of flight, then the last gap.
    sx, sy, sz = c_bi[0, 0], c_bi[0, 1], c_bi[0, 2]
    t_tof = -(x * sx + y * sy + z * sz) / (vx * sx + vy * sy + vz * sz)
    h = t_tof / coast_steps
    ex, ey, ez, evx, evy, evz = x, y, z, vx, vy, vz
    for _ in range(coast_steps):
        ex, ey, ez, evx, evy, evz = _rk4_coast(mu, tide, s0, s1, s2, ex, ey, ez, evx, evy, evz, h)
    t_rest = -(ex * sx + ey * sy + ez * sz) / (evx * sx + evy * sy + evz * sz)
    bx, by, bz = ex + evx * t_rest, ey + evy * t_rest, ez + evz * t_rest
    b_t = c_bi[1, 0] * bx + c_bi[1, 1] * by + c_bi[1, 2] * bz
    b_r = c_bi[2, 0] * bx + c_bi[2, 1] * by + c_bi[2, 2] * bz
    miss_t, miss_r = b_t - prm[AIM_FINAL], b_r - prm[AIM_FINAL + 1]
    fuel = prm[MASS] - m
    t_go = np.sqrt(rh0 * rh0 + rh1 * rh1 + rh2 * rh2) / np.sqrt(vh0 * vh0 + vh1 * vh1 + vh2 * vh2)
    out[1] = np.sqrt(miss_t * miss_t + miss_r * miss_r)
    out[2], out[3], out[4], out[5] = miss_t, miss_r, b_t, b_r
    out[6], out[7], out[8], out[9] = dv_total, firings, burn_time, fuel
    out[10] = np.sqrt((rh0 - x) ** 2 + (rh1 - y) ** 2 + (rh2 - z) ** 2)
    out[11] = _sigma_b(p, t_go, c_bi)
    out[12] = 1e6 * np.sqrt(los_error_sq / max(2 * images_used, 1))
    status = STATUS_PROPELLANT if fuel > prm[PROPELLANT] else STATUS_OK
    for j in range(1, N_OUT):
        if not np.isfinite(out[j]):
            status = STATUS_NAN
    out[0] = status


@njit(parallel=True, **_JIT)
def simulate_fed(
    prm, c_bi, p0, n_images, steps, coast_steps, fixed, burns, images, do_images, do_steps, out
):
    """Runs ``0..N-1`` with the normals of gnc_jax's layout: ``fixed`` (N, 15), ``burns``
    (N, 64, 14), ``images`` (N, n_images, 8); outcomes into ``out`` (N, N_OUT)."""
    for i in prange(fixed.shape[0]):
        _run(
            prm, c_bi, p0, n_images, steps, coast_steps, False, fixed[i], burns[i], images[i],
            do_images, do_steps, out[i],
        )  # fmt: skip


@njit(parallel=True, **_JIT)
def simulate_own(prm, c_bi, p0, n_images, steps, coast_steps, seed, do_images, do_steps, out):
    """Runs ``0..N-1`` drawing their own normals: run ``i`` seeds the thread's generator with
    ``seed + i`` (reproducible whatever the thread schedule); outcomes into ``out``."""
    fixed = np.zeros(N_FIXED)
    burns, images = np.zeros((1, BURN_DRAWS)), np.zeros((1, IMAGE_DRAWS))
    for i in prange(out.shape[0]):
        np.random.seed(seed + i)
        _run(
            prm, c_bi, p0, n_images, steps, coast_steps, True, fixed, burns, images,
            do_images, do_steps, out[i],
        )  # fmt: skip


# --------------------------------------------------------------------------------------------
# Python entry points


@functools.cache
def _draws_function():
    from gnc_jax.systems.impactor.draws import run_draws

    def draws(sim, seed, idx):
        return jax.vmap(lambda i: run_draws(sim, gj.run_key(seed, i)))(idx)

    return jax.jit(draws)


def gnc_jax_draws(sim, runs, seed=0, start=0):
    """gnc_jax's standard normals of runs ``start..start+runs-1`` of ``sim`` (an
    ``ImpactorSimulation``; ``run_draws`` of each run's key), stacked:
    ``(fixed (N, 15), burns (N, 64, 14), images (N, n_images, 8))``."""
    d = _draws_function()(sim, jnp.asarray(seed, jnp.uint32), jnp.arange(start, start + runs))
    fixed = np.concatenate(
        [
            np.asarray(d[k])
            for k in (
                "delivery",
                "knowledge_position",
                "knowledge_velocity",
                "attitude_bias",
                "accel_bias",
            )
        ],
        axis=1,
    )
    return (
        np.ascontiguousarray(fixed),
        np.ascontiguousarray(np.asarray(d["burns"])),
        np.ascontiguousarray(np.asarray(d["images"])),
    )


def _as_dict(out):
    d = {name: out[:, j].copy() for j, name in enumerate(OUT_FIELDS)}
    d["status"] = d["status"].astype(np.int32)
    d["firings"] = d["firings"].astype(np.int32)
    return d


def run_fed(scenario, fixed, burns, images, do_images=True, do_steps=True):
    """Outcomes (dict of arrays, OUT_FIELDS) of the runs whose normals are given."""
    prm, c_bi, p0, n_images, steps, coast = problem(scenario)
    if images.shape[1:] != (n_images, IMAGE_DRAWS):
        raise ValueError(f"images: shape {images.shape}; expected (N, {n_images}, {IMAGE_DRAWS})")
    out = np.empty((fixed.shape[0], N_OUT))
    simulate_fed(
        prm, c_bi, p0, n_images, steps, coast, fixed, burns, images, do_images, do_steps, out
    )
    return _as_dict(out)


def run_own(scenario, runs, seed=0, do_images=True, do_steps=True):
    """Outcomes of ``runs`` runs drawing their own normals in the kernel (run i: seed + i)."""
    prm, c_bi, p0, n_images, steps, coast = problem(scenario)
    if not 0 <= seed and seed + runs <= 2**32:
        raise ValueError("seed + runs must fit in 32 bits (numba's np.random.seed)")
    out = np.empty((runs, N_OUT))
    simulate_own(prm, c_bi, p0, n_images, steps, coast, seed, do_images, do_steps, out)
    return _as_dict(out)


# --------------------------------------------------------------------------------------------
# Benchmark


def _gnc_jax_timers(scenario, n, batch=True):
    """Timers (each returns one wall, s) of gnc_jax's study of runs 0..n-1: ``run_study`` as a
    user calls it (its executable is cached, so a repeat does not recompile) and one sharded
    vmapped call of all runs, as ``benchmarks/impactor.py`` times it (``_timing.time_batch``).
    Also returns the study (its compile time) and the batch's compile time. ``batch=False``:
    no batch timer (None)."""
    from gnc_jax.montecarlo import batch_function

    study = gj.run_study(scenario, runs=n, seed=0, progress=False)  # compiles

    def study_wall():
        c0 = time.process_time()
        wall = gj.run_study(scenario, runs=n, seed=0, progress=False).summary()["wall_s"]
        return wall, time.process_time() - c0

    if not batch:
        return study_wall, None, study, None
    system = gj.get_system(scenario.kind)
    sim, law = gj.build(scenario)
    fn, n_dev = batch_function(system)
    n_pad = -(-n // n_dev) * n_dev
    seed, idx = jnp.asarray(0, jnp.uint32), jnp.arange(n_pad)
    t0 = time.perf_counter()
    compiled = fn.lower(sim, law, seed, idx).compile()
    batch_compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(sim, law, seed, idx))

    def batch_wall():
        t0, c0 = time.perf_counter(), time.process_time()
        jax.block_until_ready(compiled(sim, law, seed, idx))
        return time.perf_counter() - t0, time.process_time() - c0

    return study_wall, batch_wall, study, batch_compile_s


def _numpy_draws(n, n_images, rng):
    return (
        rng.standard_normal((n, N_FIXED)),
        rng.standard_normal((n, N_BURN_INTERVALS, BURN_DRAWS)),
        rng.standard_normal((n, n_images, IMAGE_DRAWS)),
    )


def _fed_timer(scenario, n, chunk):
    """Timer of the fed kernel over runs 0..n-1 in chunks of at most ``chunk`` runs (the
    normals of 10,000 runs are 0.7 GB): returns the kernel wall summed over the chunks and,
    apart, the walls of making the same normals with gnc_jax's ``run_draws`` (jitted, vmapped,
    one call per chunk) and with numpy's generator."""
    prm, c_bi, p0, n_images, steps, coast = problem(scenario)
    sim, _ = gj.build(scenario)
    out = np.empty((min(n, chunk), N_OUT))
    rng = np.random.default_rng(0)
    gnc_jax_draws(sim, min(n, chunk))  # compile the draw function

    def timer():
        kernel_s = kernel_cpu_s = jax_draw_s = numpy_draw_s = 0.0
        for start in range(0, n, chunk):
            m = min(chunk, n - start)
            t0 = time.perf_counter()
            fixed, burns, images = gnc_jax_draws(sim, m, seed=0, start=start)
            jax_draw_s += time.perf_counter() - t0
            t0 = time.perf_counter()
            _numpy_draws(m, n_images, rng)
            numpy_draw_s += time.perf_counter() - t0
            t0, c0 = time.perf_counter(), time.process_time()
            simulate_fed(
                prm, c_bi, p0, n_images, steps, coast, fixed, burns, images, True, True, out[:m]
            )
            kernel_s += time.perf_counter() - t0
            kernel_cpu_s += time.process_time() - c0
        return kernel_s, kernel_cpu_s, jax_draw_s, numpy_draw_s

    return timer


def _own_timer(scenario, n, do_images=True, do_steps=True):
    prm, c_bi, p0, n_images, steps, coast = problem(scenario)
    out = np.empty((n, N_OUT))

    def timer():
        t0, c0 = time.perf_counter(), time.process_time()
        simulate_own(prm, c_bi, p0, n_images, steps, coast, 0, do_images, do_steps, out)
        return time.perf_counter() - t0, time.process_time() - c0

    return timer


def _interleaved_best(timers, repeats):
    """Best (smallest) result of each timer over ``repeats`` rounds, the timers taking turns
    within a round so that a change of the machine's load reaches them alike. A timer returning
    a tuple is minimised component by component."""
    best = {}
    for _ in range(repeats):
        for name, timer in timers.items():
            value = np.atleast_1d(timer())
            best[name] = np.minimum(best.get(name, value), value)
    return {k: (tuple(float(x) for x in v) if len(v) > 1 else float(v[0])) for k, v in best.items()}


def _profile(scenario, n, repeats):
    """Where the kernel's time goes, by switching its parts off (fed gnc_jax's normals, so no
    generator cost) and by the difference of the own-draws and fed kernels; in CPU time per
    run (the variants take turns, best of ``repeats``)."""
    prm, c_bi, p0, n_images, steps, coast = problem(scenario)
    sim, _ = gj.build(scenario)
    draws = gnc_jax_draws(sim, n)
    out = np.empty((n, N_OUT))

    def fed(do_images, do_steps):
        def timer():
            t0, c0 = time.perf_counter(), time.process_time()
            simulate_fed(prm, c_bi, p0, n_images, steps, coast, *draws, do_images, do_steps, out)
            return time.perf_counter() - t0, time.process_time() - c0

        return timer

    best = _interleaved_best(
        {
            "full": fed(True, True),
            "images": fed(True, False),
            "control": fed(False, True),
            "neither": fed(False, False),
            "own": _own_timer(scenario, n),
        },
        repeats,
    )
    cpu = {k: 1e6 * v[1] / n for k, v in best.items()}  # us per run
    parts = (
        ("control steps (law, engine, RK4, estimate)", cpu["control"] - cpu["neither"]),
        ("image updates (camera, EKF, plan, covariance)", cpu["images"] - cpu["neither"]),
        ("initial state, coast, outcome", cpu["neither"]),
        ("in-kernel normals (own - fed)", cpu["own"] - cpu["full"]),
    )
    return [
        dict(
            name=f"numba profile: {name}",
            runs=n,
            cpu_us_per_run=us,
            fraction_of_own=us / cpu["own"],
            note=f"{100 * us / cpu['own']:.0f} % of the own-draws kernel's CPU time",
        )
        for name, us in parts
    ]


def _compile_times(scenario):
    """First-call wall of each kernel in this process (compile, or load from numba's on-disk
    cache) and whether the cache answered."""
    prm, c_bi, p0, n_images, steps, coast = problem(scenario)
    fixed, burns, images = gnc_jax_draws(gj.build(scenario)[0], 2)
    out = np.empty((2, N_OUT))
    times = {}
    for name, call in (
        (
            "fed",
            lambda: simulate_fed(
                prm, c_bi, p0, n_images, steps, coast, fixed, burns, images, True, True, out
            ),
        ),
        (
            "own",
            lambda: simulate_own(prm, c_bi, p0, n_images, steps, coast, 0, True, True, out),
        ),
    ):
        kernel = simulate_fed if name == "fed" else simulate_own
        hits0 = sum(kernel.stats.cache_hits.values())
        t0 = time.perf_counter()
        call()
        times[name] = (time.perf_counter() - t0, sum(kernel.stats.cache_hits.values()) > hits0)
    return times


def _cold_compile_s():
    """Compile time of both kernels with an empty numba cache, in a fresh process (s), or
    None when the subprocess fails."""
    import subprocess
    import tempfile

    code = (
        "import sys, time\n"
        "import numpy as np\n"
        f"sys.path.insert(0, {str(ROOT)!r})\n"
        "import gnc_jax as gj\n"
        f"import {MODULE} as m\n"
        f"sc = gj.load_scenario({SCENARIO!r})\n"
        "prm, c, p0, ni, st, co = m.problem(sc)\n"
        "f, s, im = np.zeros((2, 15)), np.zeros((2, 8, 4)), np.zeros((2, ni, 18))\n"
        "out = np.empty((2, m.N_OUT))\n"
        "t0 = time.perf_counter()\n"
        "m.simulate_fed(prm, c, p0, ni, st, co, f, s, im, True, True, out)\n"
        "t1 = time.perf_counter()\n"
        "m.simulate_own(prm, c, p0, ni, st, co, 0, True, True, out)\n"
        "print(t1 - t0, time.perf_counter() - t1)\n"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        try:
            res = subprocess.run(
                [sys.executable, "-c", code],
                env=env,
                capture_output=True,
                text=True,
                timeout=600,
                check=True,
            )
            fed, own = (float(v) for v in res.stdout.split()[-2:])
            return fed, own
        except (subprocess.SubprocessError, ValueError):
            return None


def _markdown(rows):
    cols = ["name", "runs", "wall_s", "per_s", "cpu_us_per_run", "ratio_gnc_jax_vs_this"]
    cols += ["compile_s", "note"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        cells = []
        for c in cols:
            v = r.get(c, "")
            if isinstance(v, float):
                v = f"{v:,.0f}" if c in ("per_s", "cpu_us_per_run") else f"{v:.3g}"
            cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def run(quick: bool = False, sizes=None, repeats: int | None = None) -> dict:
    """The numba peer's benchmark rows (see the module docstring)."""
    title = "numba peer of the deep-impact-los closed loop"
    if numba is None:
        return {"title": title, "rows": [], "markdown": "numba is not installed", "notes": []}
    sizes = sizes or ([500] if quick else [2000, 10000])
    repeats = repeats or (2 if quick else 3)
    chunk = 2000
    scenario = gj.load_scenario(SCENARIO)
    sim, _ = gj.build(scenario)
    rows, notes = [], []
    threads = numba.get_num_threads()

    first = _compile_times(scenario)
    cold = None if quick else _cold_compile_s()
    for kind in ("fed", "own"):
        row = dict(
            name=f"numba compile ({kind})",
            runs=0,
            compile_s=first[kind][0],
            note="first call: " + ("loaded from numba's cache" if first[kind][1] else "compiled"),
        )
        if cold is not None:
            row["cold_compile_s"] = cold[0 if kind == "fed" else 1]
            row["note"] += f"; empty cache in a fresh process: {row['cold_compile_s']:.1f} s"
        rows.append(row)

    for n in sizes:
        # quick: one chunk, so run_study times the same executable as the batch function.
        study_wall, batch_wall, study, batch_compile_s = _gnc_jax_timers(scenario, n, not quick)
        timers = {"study": study_wall, "batch": batch_wall}
        timers.update(fed=_fed_timer(scenario, n, chunk), own=_own_timer(scenario, n))
        best = _interleaved_best({k: v for k, v in timers.items() if v is not None}, repeats)
        machine = study.summary()["machine"]
        gj_rate = n / best["study"][0]
        rows.append(
            dict(
                name="gnc_jax run_study",
                runs=n,
                wall_s=best["study"][0],
                per_s=gj_rate,
                cpu_us_per_run=1e6 * best["study"][1] / n,
                compile_s=study.compile_s,
                devices=study.n_devices,
                note=f"chunks of {study.chunk_size}",
            )
        )
        if "batch" in best:
            rows.append(
                dict(
                    name="gnc_jax batch_function",
                    runs=n,
                    wall_s=best["batch"][0],
                    per_s=n / best["batch"][0],
                    cpu_us_per_run=1e6 * best["batch"][1] / n,
                    compile_s=batch_compile_s,
                    note="one sharded call of all runs, as benchmarks/impactor.py",
                )
            )
        batch_s = best["batch"][0] if "batch" in best else None
        kernel_s, kernel_cpu_s, jax_draw_s, np_draw_s = best["fed"]
        rows.append(
            dict(
                name="numba fed (gnc_jax's normals)",
                runs=n,
                wall_s=kernel_s,
                per_s=n / kernel_s,
                cpu_us_per_run=1e6 * kernel_cpu_s / n,
                ratio_gnc_jax_vs_this=gj_rate / (n / kernel_s),
                draw_s_run_draws=jax_draw_s,
                draw_s_numpy=np_draw_s,
                per_s_with_numpy_draws=n / (kernel_s + np_draw_s),
                per_s_with_run_draws=n / (kernel_s + jax_draw_s),
                threads=threads,
                note=(
                    f"draws excluded: run_draws {jax_draw_s:.2f} s, numpy {np_draw_s:.2f} s; "
                    f"with numpy draws {n / (kernel_s + np_draw_s):,.0f}/s"
                ),
            )
        )
        if batch_s is not None:
            rows[-1]["ratio_gnc_jax_batch_vs_this"] = kernel_s / batch_s
        own_s, own_cpu_s = best["own"]
        rows.append(
            dict(
                name="numba own draws",
                runs=n,
                wall_s=own_s,
                per_s=n / own_s,
                cpu_us_per_run=1e6 * own_cpu_s / n,
                ratio_gnc_jax_vs_this=gj_rate / (n / own_s),
                threads=threads,
                note="np.random.standard_normal in the kernel, only what is used",
            )
        )
        if batch_s is not None:
            rows[-1]["ratio_gnc_jax_batch_vs_this"] = own_s / batch_s

    rows += _profile(scenario, min(sizes[0], chunk), repeats)

    for n in sizes:
        fed, own = (
            next(r for r in rows if r["runs"] == n and r["name"].startswith(name))
            for name in ("numba fed", "numba own")
        )
        notes.append(
            f"N = {n}: gnc_jax run_study / numba throughput = "
            f"{fed['ratio_gnc_jax_vs_this']:.2f} (numba fed, draws excluded), "
            f"{own['ratio_gnc_jax_vs_this']:.2f} (numba drawing its own normals)."
        )
    notes += [
        f"machine: {machine}",
        f"Scenario {SCENARIO}: {sim.n_images} images x {sim.steps_per_image} control steps per "
        f"run; numba {numba.__version__} with {threads} threads "
        f"(layer {numba.threading_layer()}); jax {jax.__version__} with {len(jax.devices())} "
        f"host devices; {platform.processor() or platform.machine()}, {os.cpu_count()} cores.",
        f"Every wall is the best of {repeats} rounds in which gnc_jax and the numba kernels take "
        "turns (compile times apart).",
        "cpu_us_per_run: the process's CPU time (all threads) per run in the same calls, less "
        "sensitive than the wall to other processes on the machine.",
        "ratio_gnc_jax_vs_this = gnc_jax run_study throughput / the numba row's throughput "
        "(>= 1: gnc_jax is faster); ratio_gnc_jax_batch_vs_this the same with gnc_jax's "
        "single sharded batch call.",
        "numba fed: gnc_jax's own normals (run_draws of every run key), drawn beforehand and "
        "excluded from the wall; the run_draws and numpy draw times of the same arrays are "
        "reported beside it (chunks of 2000 runs). Outcomes equal gnc_jax's run for run "
        "(tests/test_peer_numba.py).",
        "numba own draws: per-thread Mersenne twister seeded seed + i per run; 8 normals per "
        "image, 4 per ignition, 6 per image interval with a burn, 15 per run. Statistically "
        "equal to gnc_jax (KS test in tests/test_peer_numba.py).",
        "Profile rows (CPU time per run): the fed kernel with its image updates or its control "
        "steps switched off, each minus the kernel with both off; the normals' cost is the "
        "own-draws kernel minus the fed one. With the control steps off the truth does not "
        "move; with the images off the law keeps its initial sigma_B and fires differently: the "
        "rows say where the time goes, not what a run costs.",
    ]
    return {"title": title, "rows": rows, "markdown": _markdown(rows), "notes": notes}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="500 runs only (under a minute)")
    p.add_argument("--sizes", type=int, nargs="+", default=None)
    p.add_argument("--repeats", type=int, default=None)
    args = p.parse_args()
    result = run(quick=args.quick, sizes=args.sizes, repeats=args.repeats)
    print(f"# {result['title']}\n")
    print(result["markdown"])
    print()
    for note in result["notes"]:
        print(f"- {note}")


if __name__ == "__main__":
    # Run under the module's importable name, so that numba's cache (which records it) serves
    # the test suite and the benchmark harness alike.
    sys.path.insert(0, str(ROOT))
    __import__(MODULE, fromlist=["main"]).main()
