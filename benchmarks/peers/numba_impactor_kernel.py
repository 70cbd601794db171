"""The kernel of the numba peer of ``deep-impact-los`` (``benchmarks/peers/numba_impactor.py``).

Scalar code, one run per call and ``prange`` over runs: vectors as three floats, the 6x6
covariance in one array per run updated in place, nothing allocated per step, branches where
the work is conditional (the engine fires in about 0.5 % of the control steps). The arithmetic
is gnc_jax's, in its order where that costs nothing: the switching test multiplied out
(``guidance.impactor.los._hard_switch``), the gravity terms only when their constants are
nonzero (``RelativeDynamics.of``), the filter's two scalar updates with 1/s
(``navigation.packed_ekf.los_gain``), the attitude rotations composed row by row
(``navigation.camera.rotate_rows``).

Where the time goes (the benchmark's profile rows: about a third in the control steps, the rest
in the image updates) decided the rest, each change leaving every outcome the same to the bit:

* the helpers of the coasting step and of the image are inlined (``inline="always"``): numba
  calls another jitted function out of line, its arrays passed as a dozen scalars each (the
  burn step stays out of line: inlining costs compile time, about 6 s for the fed kernel);
* the step compares integers with the steps of the cutoff and the retarget, found once per
  image interval, instead of forming each step's time;
* the switching test divides for the one-step floor only where the engine may open: with the
  engine off, a lower bound of the floor that already keeps it off decides (the test grows
  harder with the floor, so the decision is the one the division would give);
* the generator's state stays in registers over a draw of several normals, the ziggurat's rare
  cases out of line.

The image update is bound by the latency of its square roots and divisions (the camera frame,
the filter's two gains, sigma_B), not by its arithmetic.

The own-draws kernel draws with xoshiro256** (seeded per run by splitmix64 of ``seed + i``)
and the ziggurat method (256 layers, 52-bit mantissas, as numpy's ``Generator``).

Every jitted function of the peer lives in this one module: numba's on-disk cache checks only
the file of the function it serves, so a kernel compiled against a helper in another file would
keep the helper's old code after an edit.
"""

import math
import sys

import numpy as np

import gnc_jax as gj
from gnc_jax.systems.impactor import draws as _layout

try:
    from numba import njit, prange
except ImportError:  # the module still imports (the suite reports the peer as missing)

    def njit(*args, **kwargs):
        return (lambda f: f) if not args or not callable(args[0]) else args[0]

    prange = range

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
S_FLOOR = 1e-200  # navigation.packed_ekf's floor of the innovation variance


# --------------------------------------------------------------------------------------------
# Random numbers: xoshiro256** and the ziggurat (numpy's, 256 layers)

_U1, _U8, _U11, _U17 = np.uint64(1), np.uint64(8), np.uint64(11), np.uint64(17)
_U7, _U57, _U45, _U19 = np.uint64(7), np.uint64(57), np.uint64(45), np.uint64(19)
_U30, _U27, _U31 = np.uint64(30), np.uint64(27), np.uint64(31)
_FIVE, _NINE, _BYTE = np.uint64(5), np.uint64(9), np.uint64(0xFF)
_MANTISSA = np.uint64(0x000FFFFFFFFFFFFF)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1, _MIX2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
ZIGGURAT_R = 3.6541528853610088  # start of the tail
_ZIGGURAT_V = 0.00492867323399  # area of each layer


def ziggurat_tables(n=256, r=ZIGGURAT_R, v=_ZIGGURAT_V, bits=52):
    """``(k, w, f)``: Marsaglia and Tsang's tables for ``n`` layers and ``bits``-bit mantissas
    (the values of numpy's ``ki_double``, ``wi_double``, ``fi_double``)."""
    m = 2.0**bits
    k, w, f = np.zeros(n, np.uint64), np.zeros(n), np.zeros(n)
    dn = tn = r
    q = v / math.exp(-0.5 * dn * dn)
    k[0], k[1] = np.uint64(int(dn / q * m)), np.uint64(0)
    w[0], w[n - 1] = q / m, dn / m
    f[0], f[n - 1] = 1.0, math.exp(-0.5 * dn * dn)
    for i in range(n - 2, 0, -1):
        dn = math.sqrt(-2.0 * math.log(v / dn + math.exp(-0.5 * dn * dn)))
        k[i + 1] = np.uint64(int(dn / tn * m))
        tn = dn
        f[i] = math.exp(-0.5 * dn * dn)
        w[i] = dn / m
    return k, w, f


_ZIG_K, _ZIG_W, _ZIG_F = ziggurat_tables()


@njit(**_JIT)
def _splitmix64(x):
    """``(next state, output)`` of splitmix64 (Steele, Lea and Flood)."""
    x = x + _GOLDEN
    z = (x ^ (x >> _U30)) * _MIX1
    z = (z ^ (z >> _U27)) * _MIX2
    return x, z ^ (z >> _U31)


@njit(**_JIT)
def seed_generator(state, seed):
    """xoshiro256** ``state`` (4 uint64) from a 64-bit seed, through splitmix64."""
    x = np.uint64(seed)
    for j in range(4):
        x, state[j] = _splitmix64(x)


@njit(inline="always", **_JIT)
def _xoshiro(s0, s1, s2, s3):
    """xoshiro256** (Blackman and Vigna): ``(the next 64 random bits, the next state)``."""
    x = s1 * _FIVE
    result = ((x << _U7) | (x >> _U57)) * _NINE
    t = s1 << _U17
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    return result, s0, s1, s2, (s3 << _U45) | (s3 >> _U19)


@njit(**_JIT)
def next_u64(s):
    """The next 64 random bits of the xoshiro256** state ``s`` (4 uint64, updated)."""
    r, s[0], s[1], s[2], s[3] = _xoshiro(s[0], s[1], s[2], s[3])
    return r


@njit(**_JIT)
def _uniform(s):
    """Uniform on [0, 1), 53 bits."""
    return np.float64(next_u64(s) >> _U11) * (1.0 / 9007199254740992.0)


@njit(**_JIT)
def _ziggurat_edge(s, idx, rabs, x):
    """The ziggurat's rare cases (1.2 % of the draws), after the layer test failed for the
    candidate ``x`` of layer ``idx``: ``(accepted, value)``; not accepted, the caller draws
    afresh."""
    if idx == 0:  # the tail beyond ZIGGURAT_R (Marsaglia's exponential method)
        while True:
            xx = -np.log1p(-_uniform(s)) / ZIGGURAT_R
            yy = -np.log1p(-_uniform(s))
            if yy + yy > xx * xx:
                return True, -(ZIGGURAT_R + xx) if (rabs >> _U8) & _U1 else ZIGGURAT_R + xx
    if (_ZIG_F[idx - 1] - _ZIG_F[idx]) * _uniform(s) + _ZIG_F[idx] < np.exp(-0.5 * x * x):
        return True, x
    return False, x


@njit(inline="always", **_JIT)
def _normals(rng, n, out):
    """``n`` standard normals into ``out`` by the ziggurat (numpy's
    ``random_standard_normal``): one 64-bit draw and a table comparison 98.8 % of the time,
    the generator's state ``rng`` held in registers meanwhile."""
    s0, s1, s2, s3 = rng[0], rng[1], rng[2], rng[3]
    i = 0
    while i < n:
        r, s0, s1, s2, s3 = _xoshiro(s0, s1, s2, s3)
        idx = np.intp(r & _BYTE)
        r = r >> _U8
        rabs = (r >> _U1) & _MANTISSA
        x = np.float64(rabs) * _ZIG_W[idx]
        if r & _U1:
            x = -x
        if rabs < _ZIG_K[idx]:
            out[i] = x
            i += 1
            continue
        rng[0], rng[1], rng[2], rng[3] = s0, s1, s2, s3
        accepted, x = _ziggurat_edge(rng, idx, rabs, x)
        s0, s1, s2, s3 = rng[0], rng[1], rng[2], rng[3]
        if accepted:
            out[i] = x
            i += 1
    rng[0], rng[1], rng[2], rng[3] = s0, s1, s2, s3


# --------------------------------------------------------------------------------------------
# Dynamics


@njit(inline="always", **_JIT)
def _gravity(mu, tide, s0, s1, s2, x, y, z):
    """Point-mass gravity of the target + linearised solar tide at (x, y, z), m/s^2.

    A term whose constant is zero is skipped (gnc_jax computes only the nonzero ones)."""
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


@njit(inline="always", **_JIT)
def _coast_increment(vx, vy, vz, c):
    """The position change of :func:`_rk4_coast` without gravity terms (``c`` = dt / 6): it
    depends on the velocity only, which such a step keeps."""
    return (
        c * (vx + 2.0 * vx + 2.0 * vx + vx),
        c * (vy + 2.0 * vy + 2.0 * vy + vy),
        c * (vz + 2.0 * vz + 2.0 * vz + vz),
    )


@njit(inline="always", **_JIT)
def _rk4_coast(mu, tide, s0, s1, s2, x, y, z, vx, vy, vz, dt):
    """:func:`_rk4` without thrust or mass flow (the same bits: those terms add zeros); without
    gravity terms every stage's velocity is v and the velocity stays (the same bits again)."""
    c = dt / 6.0
    if mu == 0.0 and tide == 0.0:
        dx, dy, dz = _coast_increment(vx, vy, vz, c)
        return x + dx, y + dy, z + dz, vx, vy, vz
    h = 0.5 * dt
    k1u, k1v, k1w = _gravity(mu, tide, s0, s1, s2, x, y, z)
    k2x, k2y, k2z = vx + h * k1u, vy + h * k1v, vz + h * k1w
    k2u, k2v, k2w = _gravity(mu, tide, s0, s1, s2, x + h * vx, y + h * vy, z + h * vz)
    k3x, k3y, k3z = vx + h * k2u, vy + h * k2v, vz + h * k2w
    k3u, k3v, k3w = _gravity(mu, tide, s0, s1, s2, x + h * k2x, y + h * k2y, z + h * k2z)
    k4x, k4y, k4z = vx + dt * k3u, vy + dt * k3v, vz + dt * k3w
    k4u, k4v, k4w = _gravity(mu, tide, s0, s1, s2, x + dt * k3x, y + dt * k3y, z + dt * k3z)
    return (
        x + c * (vx + 2.0 * k2x + 2.0 * k3x + k4x),
        y + c * (vy + 2.0 * k2y + 2.0 * k3y + k4y),
        z + c * (vz + 2.0 * k2z + 2.0 * k3z + k4z),
        vx + c * (k1u + 2.0 * k2u + 2.0 * k3u + k4u),
        vy + c * (k1v + 2.0 * k2v + 2.0 * k3v + k4v),
        vz + c * (k1w + 2.0 * k2w + 2.0 * k3w + k4w),
    )


# --------------------------------------------------------------------------------------------
# Camera, filter, plan

_SINC = tuple((-1) ** n / math.factorial(2 * n + 1) for n in range(16))
_COSC = tuple((-1) ** n / math.factorial(2 * n + 2) for n in range(16))


@njit(inline="always", **_JIT)
def _series(c, x):
    acc = c[15]
    for n in range(14, -1, -1):
        acc = acc * x + c[n]
    return acc


@njit(inline="always", **_JIT)
def _rotate(t0, t1, t2, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """R C, row by row, for R the rotation of the rotation vector (t0, t1, t2) and C the rows
    (a, b, c): cos(a) I + (sin(a)/a) [t x] + ((1 - cos a)/a^2) t t^T with both ratios as
    16-term power series in a^2 (``navigation.camera.small_rotation_entries``); row i of the
    product is R[i][1] b + R[i][2] c + R[i][0] a (``rotate_rows``)."""
    q = t0 * t0 + t1 * t1 + t2 * t2
    s = _series(_SINC, q)
    k = _series(_COSC, q)
    d = 1.0 - k * q
    s0, s1, s2 = s * t0, s * t1, s * t2
    r00, r01, r02 = d + k * t0 * t0, k * t0 * t1 - s2, k * t0 * t2 + s1
    r10, r11, r12 = k * t1 * t0 + s2, d + k * t1 * t1, k * t1 * t2 - s0
    r20, r21, r22 = k * t2 * t0 - s1, k * t2 * t1 + s0, d + k * t2 * t2
    return (
        r01 * b0 + r02 * c0 + r00 * a0,
        r01 * b1 + r02 * c1 + r00 * a1,
        r01 * b2 + r02 * c2 + r00 * a2,
        r11 * b0 + r12 * c0 + r10 * a0,
        r11 * b1 + r12 * c1 + r10 * a1,
        r11 * b2 + r12 * c2 + r10 * a2,
        r21 * b0 + r22 * c0 + r20 * a0,
        r21 * b1 + r22 * c1 + r20 * a1,
        r21 * b2 + r22 * c2 + r20 * a2,
    )


@njit(inline="always", **_JIT)
def _sigma_b(p, t_go, c_bi):
    """sqrt(sT^2 + sR^2) of the position covariance mapped to impact along a straight line
    (seed 000 eqs. 8-11): P_rr + t_go (P_rv + P_vr) + t_go^2 P_vv seen along T and R, m."""
    tt = t_go * t_go
    # the mapped block is symmetric to the bit (p is, and its two cross terms commute)
    p00 = p[0, 0] + t_go * (p[0, 3] + p[3, 0]) + tt * p[3, 3]
    p01 = p[0, 1] + t_go * (p[0, 4] + p[3, 1]) + tt * p[3, 4]
    p02 = p[0, 2] + t_go * (p[0, 5] + p[3, 2]) + tt * p[3, 5]
    p11 = p[1, 1] + t_go * (p[1, 4] + p[4, 1]) + tt * p[4, 4]
    p12 = p[1, 2] + t_go * (p[1, 5] + p[4, 2]) + tt * p[4, 5]
    p22 = p[2, 2] + t_go * (p[2, 5] + p[5, 2]) + tt * p[5, 5]
    d = 0.0
    for a in range(1, 3):
        c0, c1, c2 = c_bi[a, 0], c_bi[a, 1], c_bi[a, 2]
        m0 = c0 * p00 + c1 * p01 + c2 * p02
        m1 = c0 * p01 + c1 * p11 + c2 * p12
        m2 = c0 * p02 + c1 * p12 + c2 * p22
        d += m0 * c0 + m1 * c1 + m2 * c2
    return np.sqrt(d)


@njit(inline="always", **_JIT)
def _plan(prm, c_bi, p, t, rh0, rh1, rh2, vh0, vh1, vh2):
    """The law's plan: sigma_B of the estimate, t_go = |aim - r_hat| / |v_hat| (eq. 9)."""
    a = AIM_FINAL if t >= prm[RETARGET] else AIM_INITIAL
    bt, br = prm[a], prm[a + 1]
    q0 = bt * c_bi[1, 0] + br * c_bi[2, 0] - rh0
    q1 = bt * c_bi[1, 1] + br * c_bi[2, 1] - rh1
    q2 = bt * c_bi[1, 2] + br * c_bi[2, 2] - rh2
    t_go = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2) / np.sqrt(vh0 * vh0 + vh1 * vh1 + vh2 * vh2)
    return _sigma_b(p, t_go, c_bi)


@njit(inline="always", **_JIT)
def _times_h(p, h0, h1, h2):
    """P h^T for h = (h0, h1, h2, 0, 0, 0) (the LOS Jacobian has no velocity columns)."""
    return (
        p[0, 0] * h0 + p[0, 1] * h1 + p[0, 2] * h2,
        p[1, 0] * h0 + p[1, 1] * h1 + p[1, 2] * h2,
        p[2, 0] * h0 + p[2, 1] * h1 + p[2, 2] * h2,
        p[3, 0] * h0 + p[3, 1] * h1 + p[3, 2] * h2,
        p[4, 0] * h0 + p[4, 1] * h1 + p[4, 2] * h2,
        p[5, 0] * h0 + p[5, 1] * h1 + p[5, 2] * h2,
    )


@njit(inline="always", **_JIT)
def _image_update(prm, c_bi, p, w, x, y, z, rh0, rh1, rh2, vh0, vh1, vh2, ab0, ab1, ab2):
    """One image and its EKF update: ``(r_hat, v_hat, squared LOS error)``; ``p`` updated in
    place. ``w``: the image's normals (front end, attitude control, attitude knowledge)."""
    sig_ctrl, sig_noise = prm[SIG_ATT_CONTROL], prm[SIG_ATT_NOISE]
    r_var = prm[SIG_IMAGE] * prm[SIG_IMAGE] + sig_noise * sig_noise
    # Camera pointed at the estimated target direction (roll from the B-plane R axis).
    up0, up1, up2 = c_bi[2, 0], c_bi[2, 1], c_bi[2, 2]
    nb = np.sqrt(rh0 * rh0 + rh1 * rh1 + rh2 * rh2)
    zc0, zc1, zc2 = -rh0 / nb, -rh1 / nb, -rh2 / nb
    xc0, xc1, xc2 = up1 * zc2 - up2 * zc1, up2 * zc0 - up0 * zc2, up0 * zc1 - up1 * zc0
    nx = np.sqrt(xc0 * xc0 + xc1 * xc1 + xc2 * xc2)
    xc0, xc1, xc2 = xc0 / nx, xc1 / nx, xc2 / nx
    yc0, yc1, yc2 = zc1 * xc2 - zc2 * xc1, zc2 * xc0 - zc0 * xc2, zc0 * xc1 - zc1 * xc0
    # True attitude: control error; believed attitude: bias + knowledge noise.
    ct = _rotate(
        sig_ctrl * w[2], sig_ctrl * w[3], sig_ctrl * w[4],
        xc0, xc1, xc2, yc0, yc1, yc2, zc0, zc1, zc2,
    )  # fmt: skip
    ce = _rotate(
        ab0 + sig_noise * w[5], ab1 + sig_noise * w[6], ab2 + sig_noise * w[7],
        ct[0], ct[1], ct[2], ct[3], ct[4], ct[5], ct[6], ct[7], ct[8],
    )  # fmt: skip
    # Predicted angles and the LOS Jacobian (position columns only).
    e0 = -(ce[0] * rh0 + ce[1] * rh1 + ce[2] * rh2)
    e1 = -(ce[3] * rh0 + ce[4] * rh1 + ce[5] * rh2)
    e2 = -(ce[6] * rh0 + ce[7] * rh1 + ce[8] * rh2)
    inv = 1.0 / e2
    zp0, zp1 = e0 * inv, e1 * inv
    h00, h01, h02 = (
        -(ce[0] - zp0 * ce[6]) * inv, -(ce[1] - zp0 * ce[7]) * inv, -(ce[2] - zp0 * ce[8]) * inv
    )  # fmt: skip
    h10, h11, h12 = (
        -(ce[3] - zp1 * ce[6]) * inv, -(ce[4] - zp1 * ce[7]) * inv, -(ce[5] - zp1 * ce[8]) * inv
    )  # fmt: skip
    # Measurement: true angles in the true camera frame + the front end's noise.
    t0 = -(ct[0] * x + ct[1] * y + ct[2] * z)
    t1 = -(ct[3] * x + ct[4] * y + ct[5] * z)
    t2 = -(ct[6] * x + ct[7] * y + ct[8] * z)
    zt0, zt1 = t0 / t2, t1 / t2
    sig_front = prm[SIG_FRONT_END]
    zm0, zm1 = zt0 + sig_front * w[0], zt1 + sig_front * w[1]
    # Two scalar updates (packed_ekf.los_gain): u = P h^T, s = h u + r, w = u / s, the second
    # angle's u and innovation at the prior's linearisation point (6-tuples, in registers).
    u1 = _times_h(p, h00, h01, h02)
    inv1 = 1.0 / (u1[0] * h00 + u1[1] * h01 + u1[2] * h02 + r_var + S_FLOOR)
    gain1 = (zm0 - zp0) * inv1
    c12 = u1[0] * h10 + u1[1] * h11 + u1[2] * h12
    w1 = (u1[0] * inv1, u1[1] * inv1, u1[2] * inv1, u1[3] * inv1, u1[4] * inv1, u1[5] * inv1)
    ph = _times_h(p, h10, h11, h12)
    u2 = (
        ph[0] - w1[0] * c12, ph[1] - w1[1] * c12, ph[2] - w1[2] * c12,
        ph[3] - w1[3] * c12, ph[4] - w1[4] * c12, ph[5] - w1[5] * c12,
    )  # fmt: skip
    inv2 = 1.0 / (u2[0] * h10 + u2[1] * h11 + u2[2] * h12 + r_var + S_FLOOR)
    da, db, dc = u1[0] * gain1, u1[1] * gain1, u1[2] * gain1
    gain2 = ((zm1 - zp1) - (h10 * da + h11 * db + h12 * dc)) * inv2
    w2 = (u2[0] * inv2, u2[1] * inv2, u2[2] * inv2, u2[3] * inv2, u2[4] * inv2, u2[5] * inv2)
    for r in range(6):
        for c in range(r, 6):
            v = p[r, c] - w1[r] * u1[c] - w2[r] * u2[c]
            p[r, c] = v
            p[c, r] = v
    return (
        rh0 + (da + u2[0] * gain2),
        rh1 + (db + u2[1] * gain2),
        rh2 + (dc + u2[2] * gain2),
        vh0 + (u1[3] * gain1 + u2[3] * gain2),
        vh1 + (u1[4] * gain1 + u2[4] * gain2),
        vh2 + (u1[5] * gain1 + u2[5] * gain2),
        (zm0 - zt0) ** 2 + (zm1 - zt1) ** 2,
    )


@njit(inline="always", **_JIT)
def _grow_covariance(p, dt, q, q_dv):
    """P <- Phi P Phi^T + Q over ``dt`` in place (``navigation.packed_ekf.propagate_packed``):
    the position block first (it reads the old cross and velocity blocks), then the cross
    block (the old velocity block), then the velocity diagonal."""
    q_rr, q_rv, q_vv = q * (dt * dt * dt) / 3.0, q * (dt * dt) / 2.0, q * dt + q_dv
    for r in range(3):
        for c in range(r, 3):
            v = p[r, c] + dt * (p[r, c + 3] + p[r + 3, c]) + dt * dt * p[r + 3, c + 3]
            if r == c:
                v += q_rr
            p[r, c] = v
            p[c, r] = v
    for r in range(3):
        for c in range(3, 6):
            v = p[r, c] + dt * p[r + 3, c]
            if c == r + 3:
                v += q_rv
            p[r, c] = v
            p[c, r] = v
    for r in range(3, 6):
        p[r, r] += q_vv


@njit(inline="always", **_JIT)
def _first_step(t_img, dt, steps, t_event, at_or_after):
    """The first step k of ``0..steps-1`` whose time t = t_img + k dt is ``>= t_event``
    (``at_or_after``) or not ``< t_event`` (the loop's two comparisons, the same where a time
    is NaN), else ``steps``. t rounded grows with k (dt > 0): the first and last steps decide
    for all but the interval that holds the event."""
    k = 0
    while k < steps:
        t = t_img + dt * k
        if (t >= t_event) if at_or_after else not (t < t_event):
            return k
        if k == 0:  # the last step: if it is before the event, so are all
            t = t_img + dt * (steps - 1)
            if not ((t >= t_event) if at_or_after else not (t < t_event)):
                return steps
        k += 1
    return steps


@njit(inline="always", **_JIT)
def _opens(rr, oo, qq, closing, open2):
    """The hard switch's opening test multiplied out (``guidance.impactor.los._hard_switch``):
    |omega| >= omega_open iff rho^2 > rho_o^2 and (opening range or |rho x rho_dot|^2
    (rho^2 - rho_o^2) >= rho_o^2 (rho . rho_dot)^2); ``open2`` = rho_o^2."""
    return rr > open2 and (not closing or oo * (rr - open2) >= open2 * qq)


@njit(inline="always", **_JIT)
def _floor_bounds(vv, close2, open2):
    """``(1 / vv, whether the switching test may bound the floor a / vv by a (1 / vv))``: where
    1 / vv and both tolerances are normal numbers (rounding then errs by 3 ulp at most)."""
    inv_vv = 1.0 / vv
    ok = 2.3e-308 <= inv_vv < 1e300 and 2.3e-308 <= close2 < 1e300 and 2.3e-308 <= open2 < 1e300
    return inv_vv, ok


@njit(**_JIT)
def _outcome(prm, c_bi, coast_steps, x, y, z, vx, vy, vz, m, rh0, rh1, rh2, vh0, vh1, vh2, p, out):
    """Coast to the B-plane (RK4 over the straight-line time of flight, then the last gap) and
    the outcome columns ``out[1:12]`` that depend on the state."""
    mu, tide, s0, s1, s2 = prm[MU], prm[TIDE], prm[SUN], prm[SUN + 1], prm[SUN + 2]
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
    t_go = np.sqrt(rh0 * rh0 + rh1 * rh1 + rh2 * rh2) / np.sqrt(vh0 * vh0 + vh1 * vh1 + vh2 * vh2)
    out[1] = np.sqrt(miss_t * miss_t + miss_r * miss_r)
    out[2], out[3], out[4], out[5] = miss_t, miss_r, b_t, b_r
    out[9] = prm[MASS] - m
    out[10] = np.sqrt((rh0 - x) ** 2 + (rh1 - y) ** 2 + (rh2 - z) ** 2)
    out[11] = _sigma_b(p, t_go, c_bi)


# --------------------------------------------------------------------------------------------
# The closed loop


@njit(**_JIT)
def _run(
    prm, c_bi, p0, n_images, steps, coast_steps, rng, fixed, burns, images, do_images, do_steps, out
):
    """One closed-loop run into ``out`` (OUT_FIELDS). ``rng``: a xoshiro256** state to draw
    the normals from, or an empty array to read them from ``fixed`` (15), ``burns``
    (64 x 14) and ``images`` (n_images x 8), gnc_jax's layout. ``do_images`` / ``do_steps``:
    the profile's switches (both True for a real run)."""
    own = rng.shape[0] > 0
    dt, image_dt = prm[DT], prm[IMAGE_DT]
    mu, tide, s0, s1, s2 = prm[MU], prm[TIDE], prm[SUN], prm[SUN + 1], prm[SUN + 2]
    free = mu == 0.0 and tide == 0.0  # no gravity term: a coasting step keeps the velocity
    c6 = dt / 6.0
    thrust_n, flow_max, cutoff, retarget = prm[THRUST], prm[FLOW], prm[CUTOFF], prm[RETARGET]
    k1sq, k2sq = prm[K1] * prm[K1], prm[K2] * prm[K2]
    c_res = 0.5 * prm[CTX_THRUST] / prm[CTX_MASS] * dt  # miss per s of t_go per step
    c_res2 = c_res * c_res
    sig_ctrl, sig_burn = prm[SIG_ATT_CONTROL], prm[SIG_BURN]
    acc_noise, acc_sig = prm[SIG_ACC_NOISE], prm[SIG_ACC_BIAS]
    fb0, fb1, fb2 = c_bi[1, 0], c_bi[1, 1], c_bi[1, 2]  # thrust direction when ZEM = 0
    ai0 = prm[AIM_INITIAL] * c_bi[1, 0] + prm[AIM_INITIAL + 1] * c_bi[2, 0]  # aim points
    ai1 = prm[AIM_INITIAL] * c_bi[1, 1] + prm[AIM_INITIAL + 1] * c_bi[2, 1]
    ai2 = prm[AIM_INITIAL] * c_bi[1, 2] + prm[AIM_INITIAL + 1] * c_bi[2, 2]
    af0 = prm[AIM_FINAL] * c_bi[1, 0] + prm[AIM_FINAL + 1] * c_bi[2, 0]
    af1 = prm[AIM_FINAL] * c_bi[1, 1] + prm[AIM_FINAL + 1] * c_bi[2, 1]
    af2 = prm[AIM_FINAL] * c_bi[1, 2] + prm[AIM_FINAL + 1] * c_bi[2, 2]

    # Per-run draws and initial conditions.
    w = np.empty(18)  # [0:15] per run, then [0:8] per image, [8:12] ignition, [12:18] accel
    if own:
        _normals(rng, N_FIXED, w)
    else:
        w[:N_FIXED] = fixed[:N_FIXED]
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

    engine_on = 0.0
    sigma_b = _plan(prm, c_bi, p, 0.0, rh0, rh1, rh2, vh0, vh1, vh2)
    throttle_prev = 0.0
    e_mag = e_p0 = e_p1 = e_p2 = 0.0  # execution error of the current firing (normals)
    q0 = q1 = q2 = qv = 0.0  # the law's rho, rho . rho_dot, |v_hat|^2 (thrust direction)
    burn_intervals = 0
    dv_total = burn_time = los_error_sq = 0.0
    firings = images_used = 0

    for i in range(n_images):
        t_img = i * image_dt
        if own:
            _normals(rng, IMAGE_DRAWS, w)
        else:
            w[:IMAGE_DRAWS] = images[i, :IMAGE_DRAWS]
        if do_images:
            rh0, rh1, rh2, vh0, vh1, vh2, err2 = _image_update(
                prm, c_bi, p, w, x, y, z, rh0, rh1, rh2, vh0, vh1, vh2, ab0, ab1, ab2
            )
            los_error_sq += err2
            images_used += 1
            sigma_b = _plan(prm, c_bi, p, t_img, rh0, rh1, rh2, vh0, vh1, vh2)
        # The switching curves' miss tolerances from sigma_B, squared (fixed over the interval).
        sb2 = sigma_b * sigma_b
        close_nav, open_nav = k2sq * sb2, k1sq * sb2
        # Loop invariants while coasting, recomputed after each burn step (the same bits).
        vv = vh0 * vh0 + vh1 * vh1 + vh2 * vh2
        inv_vv, bounds_ok = _floor_bounds(vv, close_nav, open_nav)
        dh0, dh1, dh2 = vh0 * dt, vh1 * dt, vh2 * dt
        dx, dy, dz = _coast_increment(vx, vy, vz, c6)
        # Execution draws of this interval's ignitions (fed: gnc_jax's burn-table row).
        row = 0 if own else burn_intervals % N_BURN_INTERVALS
        ignitions_image = 0
        mom_a = mom_b = mom_c = 0.0
        burn_image = 0.0
        # The steps at which t = t_img + k dt reaches the cutoff and the retarget time.
        k_cut = _first_step(t_img, dt, steps, cutoff, False)
        k_ret = _first_step(t_img, dt, steps, retarget, True)
        for k in range(steps if do_steps else 0):
            throttle = 0.0
            if k < k_cut:
                # The hard switch multiplied out (guidance.impactor.los._hard_switch):
                # |omega| >= omega_open iff rho^2 > rho_o^2 and (opening range or
                # |rho x rho_dot|^2 (rho^2 - rho_o^2) >= rho_o^2 (rho . rho_dot)^2); likewise
                # for closing at rho_c.
                if k >= k_ret:
                    q0, q1, q2 = af0 - rh0, af1 - rh1, af2 - rh2  # rho; rho_dot = -v_hat
                else:
                    q0, q1, q2 = ai0 - rh0, ai1 - rh1, ai2 - rh2
                rr = q0 * q0 + q1 * q1 + q2 * q2
                qv = -(q0 * vh0 + q1 * vh1 + q2 * vh2)  # rho . rho_dot
                o0, o1, o2 = q1 * vh2 - q2 * vh1, q2 * vh0 - q0 * vh2, q0 * vh1 - q1 * vh0
                oo = o0 * o0 + o1 * o1 + o2 * o2  # |rho x rho_dot|^2
                a_floor = c_res2 * rr  # the one-step floor (miss_limits): a_floor / vv
                qq = qv * qv
                closing = qv < 0.0
                # The engine off stays off unless the opening test passes, and that test only
                # gets harder as rho_o^2 grows: where it fails at a lower bound of rho_o^2 the
                # floor's division is not needed (a_floor / vv rounded is within a_floor *
                # (1 / vv) (1 +- 2^-50) where both are normal numbers).
                # The floor is on sigma_B^2 (a_floor / vv / k2^2), both tolerances scaled
                # from it: rounding is monotone, so a lower bound of a_floor / vv gives one of
                # rho_o^2.
                a_lo = a_floor * inv_vv
                if not (
                    engine_on == 0.0
                    and bounds_ok
                    and 2.3e-308 <= a_lo < 1e300
                    and not _opens(
                        rr, oo, qq, closing,
                        k1sq * max(sb2, a_lo * (1.0 - 2.0**-50) / k2sq),
                    )
                ):  # fmt: skip
                    s2_floor = max(sb2, a_floor / vv / k2sq)
                    close2 = k2sq * s2_floor
                    open2 = k1sq * s2_floor
                    if _opens(rr, oo, qq, closing, open2):
                        engine_on = 1.0
                    elif (
                        rr <= close2
                        or (closing and oo * (rr - close2) <= close2 * qq)
                        or (not closing and oo == 0.0 and qv == 0.0)
                    ):
                        engine_on = 0.0
                throttle = engine_on
            else:
                engine_on = 0.0
            if throttle > 0.0:
                if throttle_prev <= 0.0:  # ignition: this firing's execution error
                    if own:
                        _normals(rng, 4, w[8:12])
                    elif ignitions_image == 0:
                        w[8:12] = burns[row, 0:4]
                    else:
                        w[8:12] = burns[row, 4:8]
                    e_mag, e_p0, e_p1, e_p2 = w[8], w[9], w[10], w[11]
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
                vv = vh0 * vh0 + vh1 * vh1 + vh2 * vh2
                inv_vv, bounds_ok = _floor_bounds(vv, close_nav, open_nav)
                dh0, dh1, dh2 = vh0 * dt, vh1 * dt, vh2 * dt
                dx, dy, dz = _coast_increment(vx, vy, vz, c6)
                th2 = throttle * throttle
                c_k = dt * (steps - k - 0.5)
                mom_a += th2
                mom_b += th2 * c_k
                mom_c += th2 * c_k * c_k
                dv_total += np.sqrt(dvt0 * dvt0 + dvt1 * dvt1 + dvt2 * dvt2)
                burn_time += tb
                burn_image += tb
            else:  # coasting: truth under gravity alone, estimate along a straight line
                if free:
                    x, y, z = x + dx, y + dy, z + dz
                else:
                    x, y, z, vx, vy, vz = _rk4_coast(mu, tide, s0, s1, s2, x, y, z, vx, vy, vz, dt)
                rh0 += dh0
                rh1 += dh1
                rh2 += dh2
            throttle_prev = throttle
        if do_images:
            if mom_a > 0.0:  # accelerometer white noise over the interval (accel_noise)
                if own:
                    _normals(rng, 6, w[12:18])
                else:
                    w[12:18] = burns[row, 8:14]
                burn_intervals += 1
                sigma_dv = acc_noise * dt
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
            _grow_covariance(p, image_dt, prm[PROCESS_NOISE], q_dv)

    _outcome(prm, c_bi, coast_steps, x, y, z, vx, vy, vz, m, rh0, rh1, rh2, vh0, vh1, vh2, p, out)
    out[6], out[7], out[8] = dv_total, firings, burn_time
    out[12] = 1e6 * np.sqrt(los_error_sq / max(2 * images_used, 1))
    status = STATUS_PROPELLANT if out[9] > prm[PROPELLANT] else STATUS_OK
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
    none = np.empty(0, np.uint64)
    for i in prange(fixed.shape[0]):
        _run(
            prm, c_bi, p0, n_images, steps, coast_steps, none, fixed[i], burns[i], images[i],
            do_images, do_steps, out[i],
        )  # fmt: skip


@njit(parallel=True, **_JIT)
def simulate_own(prm, c_bi, p0, n_images, steps, coast_steps, seed, do_images, do_steps, out):
    """Runs ``0..N-1`` drawing their own normals: run ``i`` from a xoshiro256** generator
    seeded with ``seed + i`` (reproducible whatever the thread schedule); outcomes into
    ``out``."""
    fixed = np.zeros(N_FIXED)
    burns, images = np.zeros((1, BURN_DRAWS)), np.zeros((1, IMAGE_DRAWS))
    for i in prange(out.shape[0]):
        rng = np.empty(4, np.uint64)
        seed_generator(rng, seed + i)
        _run(
            prm, c_bi, p0, n_images, steps, coast_steps, rng, fixed, burns, images,
            do_images, do_steps, out[i],
        )  # fmt: skip


@njit(**_JIT)
def normals(seed, n):
    """``n`` standard normals of the generator seeded with ``seed`` (the kernel's draws)."""
    rng = np.empty(4, np.uint64)
    seed_generator(rng, seed)
    out = np.empty(n)
    _normals(rng, n, out)
    return out
