"""Open-loop propagation against the tools a user would pick instead (peers).

    python benchmarks/peers/propagation.py [--quick] [--arcs 1000] [--repeats 5]

Two ensembles of open-loop arcs, the same equations on every side, each propagator's final
position compared with a tight reference, throughput in arcs/s (compile time apart):

* **entry** -- `gnc_jax.dynamics.entry.entry_vector_field` (ECI Cartesian state, J2 gravity,
  atmosphere co-rotating with the Earth, lift and drag at a constant bank) for 800 s (the
  skip-entry predictor's arc: first dip and Kepler phase) from the ``lunar-skip-entry`` entry
  interface, dispersed by the scenario's own draws (`simulation.capsule.dispersed_entry`:
  state, C_L, C_D, mass, density), the bank uniform in 45-65 deg (every arc skips; its
  lowest point is 58-64 km). The atmosphere is the package's *exponential* model (scenario
  rho0 and scale height) on every side: the package's default US76 is a 1000-node PCHIP
  table, which heyoka's expression system cannot hold (one row times gnc_jax with US76 to
  show its extra cost). Propagators: gnc_jax's vmapped fixed-step ``lax.scan``
  (`integrate_fixed`, RK4 and Butcher's RK6) sharded over the host devices as `montecarlo`
  does; the same scan on a component-wise transcription of the field (structure of arrays
  under vmap: the layout of the package's closed loops and skip-entry predictor,
  `dynamics.entry.EntryStateXYZ`; the plain rows measure what a (batch, 3) layout costs);
  heyoka.py's Taylor integrator in batch (SIMD) mode, one batch integrator per thread looping
  over the batches (the documented ``ensemble_propagate_until_batch`` deep-copies the
  integrator for every batch and is 10x slower here: one row shows it); a hand-written numba
  RK4 (``prange`` over arcs); a scipy ``solve_ivp`` (DOP853) loop. Reference: scipy DOP853 at
  rtol 1e-13 with a plain-Python transcription of the field.
* **cruise** -- `gnc_jax.dynamics.heliocentric.vector_field` (Sun, 8 planets from the plan94
  mean elements, cannonball radiation pressure) with the ``phoenix-midcourse`` force model,
  from the first fix (E-238 d) to E-10 d (228 days; the cruise a prediction integrates before
  the Mars approach), states dispersed by the scenario's 289 km / 0.577 m/s per axis around
  the scenario's Sun-only Lambert conic (the design's full-model retarget, a few m/s, is
  skipped: it changes where the arc meets Mars, not the cruise). gnc_jax as the midcourse
  system propagates (diffrax Dopri8, rtol 1e-13, atol 1e-7, planets from the quintic Hermite
  table of plan94), at looser tolerances, with plan94 evaluated directly (heyoka's exact
  equations), and fixed-step RK4/RK6 scans; heyoka with plan94 written in its expression
  system (``kepE`` for Kepler's equation, compact mode); a ``solve_ivp`` loop whose field
  takes the planets from ERFA's ``plan94``. Reference: heyoka at tol 1e-15 in high-accuracy
  mode (the scipy loop at rtol 1e-13 agrees with it to centimetres).

The summary compares, at equal accuracy (the fastest setting of each tool whose worst final
position error over the checked arcs meets the requirement: 30 m and 5 m for the entry
predictor, whose corrector works to 5 km in range; 1 m, the B-plane targeter's tolerance, and
5 cm for the cruise), gnc_jax's throughput with each peer's, and profiles the gnc_jax /
heyoka gap per core: evaluations per arc (RK stages; Taylor steps x the cost of a step in
heyoka's own compiled right-hand-side evaluations) and the cost of one evaluation.
"""

import argparse
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

import gnc_jax as gj  # before any JAX computation: float64 and one XLA device per core
from gnc_jax.dynamics import ephemeris
from gnc_jax.dynamics.atmosphere import Atmosphere
from gnc_jax.dynamics.entry import EntryArgs, EntryState, entry_vector_field
from gnc_jax.dynamics.heliocentric import HeliocentricModel, vector_field
from gnc_jax.integrate import RK4, RK6_BUTCHER, integrate_fixed

ENTRY_ARC_S = 800.0
ENTRY_BANK_DEG = (45.0, 65.0)
ENTRY_REQUIREMENT_M = 30.0  # the predictor's need (corrector tolerance 5 km in range)
CRUISE_END_BEFORE_ENCOUNTER_S = 10 * 86400.0
CRUISE_REQUIREMENT_M = 1.0  # the B-plane targeter's tolerance
DAY_S = 86400.0
COMPONENTS = "gnc_jax (component-wise)"  # tool name of the structure-of-arrays variant


# --------------------------------------------------------------------------------------------
# Timing and sharding


def _best_of(fn, repeats):
    """Smallest wall time (s) of ``repeats`` calls of ``fn`` (JAX outputs waited for)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return min(times)


def _sharded(one):
    """``f(shared, batch)``: ``one(shared, item)`` vmapped over the leading axis of ``batch``,
    split over the host devices the way `gnc_jax.montecarlo.batch_function` splits runs."""
    batched = jax.vmap(one, in_axes=(None, 0))
    devices = jax.devices()
    if len(devices) == 1:
        return jax.jit(batched)
    mesh = Mesh(np.array(devices), ("arcs",))
    return jax.jit(
        jax.shard_map(
            batched,
            mesh=mesh,
            in_specs=(PartitionSpec(), PartitionSpec("arcs")),
            out_specs=PartitionSpec("arcs"),
            check_vma=False,
        )
    )


def _compile_and_time(fn, shared, batch, repeats):
    """``(outputs, compile_s, wall_s)`` of a jitted ``fn(shared, batch)``."""
    t0 = time.perf_counter()
    compiled = fn.lower(shared, batch).compile()
    compile_s = time.perf_counter() - t0
    out = jax.block_until_ready(compiled(shared, batch))
    return out, compile_s, _best_of(lambda: compiled(shared, batch), repeats)


def _position_errors(final, reference):
    """Final-position errors (m) of the rows of ``final`` against ``reference``."""
    return np.linalg.norm(np.asarray(final)[:, :3] - np.asarray(reference)[:, :3], axis=1)


# --------------------------------------------------------------------------------------------
# Entry: the problem and its transcriptions


class EntryEnsemble(NamedTuple):
    """Dispersed entry arcs: gnc_jax pytrees and the same numbers as plain arrays.

    ``params`` rows are (k_D, k_L, cos sigma, sin sigma) with k = rho0 s_rho S C / (2 m) (1/m),
    so that drag = -k_D rho_n |v_rel| v_rel and |lift| = k_L rho_n |v_rel|^2 with
    rho_n = exp(-h / H); ``consts`` is (mu, R_E, J2, omega_E, H).
    """

    earth: object
    y0: EntryState  # leaves (n, 3)
    batch: tuple  # (y0, vehicle, atmosphere, bank), leaves with a leading n axis
    states: np.ndarray  # (n, 6)
    params: np.ndarray  # (n, 4)
    consts: np.ndarray  # (5,)


def entry_ensemble(n: int, seed: int = 0, model: str = "exponential") -> EntryEnsemble:
    """``n`` arcs from the ``lunar-skip-entry`` entry interface (run keys ``seed``, 0..n-1)."""
    from gnc_jax.systems.capsule import simulation as capsule

    sim = capsule.build(gj.load_scenario("lunar-skip-entry"))
    air = sim.atmosphere
    sim = eqx.tree_at(
        lambda s: s.atmosphere,
        sim,
        Atmosphere(model=model, rho0=air.rho0, scale_height_m=air.scale_height_m),
    )
    lo, hi = (math.radians(b) for b in ENTRY_BANK_DEG)

    def draw(i):
        key = gj.run_key(seed, i)
        y, vehicle, atmosphere, _ = capsule.dispersed_entry(sim, key)
        bank = jax.random.uniform(jax.random.fold_in(key, 2), (), minval=lo, maxval=hi)
        return y, vehicle, atmosphere, bank

    y0, vehicle, atmosphere, bank = jax.jit(jax.vmap(draw))(jnp.arange(n))
    f = lambda x: np.asarray(x, dtype=np.float64)  # noqa: E731
    k = 0.5 * f(atmosphere.rho0) * f(atmosphere.density_scale) * f(vehicle.reference_area_m2)
    k = k / f(vehicle.mass_kg)
    params = np.stack(
        [
            k * f(vehicle.drag_coefficient) * f(vehicle.drag_scale),
            k * f(vehicle.lift_coefficient) * f(vehicle.lift_scale),
            np.cos(f(bank)),
            np.sin(f(bank)),
        ],
        axis=1,
    )
    e = sim.earth
    consts = f([e.mu, e.equatorial_radius_m, e.j2, e.rotation_rate, air.scale_height_m])
    states = np.concatenate([f(y0.r), f(y0.v)], axis=1)
    return EntryEnsemble(e, y0, (y0, vehicle, atmosphere, bank), states, params, consts)


def _entry_arc(earth, item, dt, n_steps, tableau):
    y, vehicle, atmosphere, bank = item
    args = EntryArgs(vehicle, earth, atmosphere, bank)
    return integrate_fixed(entry_vector_field, 0.0, y, dt, n_steps, args, tableau=tableau)


def entry_rhs(s, p, c, out):
    """`entry_vector_field` with the exponential atmosphere, scalar by scalar (plain Python;
    numba compiles the same function). ``s`` state (6,), ``p`` `EntryEnsemble` params (4,),
    ``c`` consts (5,); writes d/dt s into ``out`` (6,)."""
    x, y, z, vx, vy, vz = s[0], s[1], s[2], s[3], s[4], s[5]
    mu, re, j2, w, scale_height = c[0], c[1], c[2], c[3], c[4]
    r2 = x * x + y * y + z * z
    r = math.sqrt(r2)
    sin_lat = z / r
    mu_r2 = mu / r2
    j2_term = j2 * (re / r) ** 2
    g_r = -mu_r2 * (1.0 + 1.5 * j2_term * (1.0 - 5.0 * sin_lat * sin_lat))
    g_z = -3.0 * mu_r2 * j2_term * sin_lat
    ux, uy, uz = x / r, y / r, z / r
    # air-relative velocity v - omega x r, omega along z
    ax_, ay_, az_ = vx + w * y, vy - w * x, vz
    speed = math.sqrt(ax_ * ax_ + ay_ * ay_ + az_ * az_)
    rho_n = math.exp(-(r - re) / scale_height)
    drag = p[0] * rho_n * speed
    lift = p[1] * rho_n * speed * speed
    hx, hy, hz = ax_ / speed, ay_ / speed, az_ / speed
    d = ux * hx + uy * hy + uz * hz
    px, py, pz = ux - d * hx, uy - d * hy, uz - d * hz
    pn = math.sqrt(px * px + py * py + pz * pz)
    px, py, pz = px / pn, py / pn, pz / pn
    qx, qy, qz = hy * pz - hz * py, hz * px - hx * pz, hx * py - hy * px  # right: v_hat x up
    cb, sb = p[2], p[3]
    out[0], out[1], out[2] = vx, vy, vz
    out[3] = g_r * ux - drag * ax_ + lift * (cb * px + sb * qx)
    out[4] = g_r * uy - drag * ay_ + lift * (cb * py + sb * qy)
    out[5] = g_r * uz + g_z - drag * az_ + lift * (cb * pz + sb * qz)


_NUMBA = {}


def numba_entry_rk4():
    """``rk4(states, params, consts, dt, n_steps) -> finals``: numba RK4 of `entry_rhs`,
    ``prange`` over arcs, the stages written as `gnc_jax.integrate.rk4_step` writes them."""
    if "rk4" in _NUMBA:
        return _NUMBA["rk4"]
    import numba

    rhs = numba.njit(entry_rhs)

    @numba.njit(parallel=True)
    def rk4(states, params, consts, dt, n_steps):
        out = np.empty_like(states)
        for i in numba.prange(states.shape[0]):
            p = params[i]
            y = states[i].copy()
            k1, k2, k3, k4, tmp = np.empty(6), np.empty(6), np.empty(6), np.empty(6), np.empty(6)
            for _ in range(n_steps):
                rhs(y, p, consts, k1)
                for j in range(6):
                    tmp[j] = y[j] + 0.5 * dt * k1[j]
                rhs(tmp, p, consts, k2)
                for j in range(6):
                    tmp[j] = y[j] + 0.5 * dt * k2[j]
                rhs(tmp, p, consts, k3)
                for j in range(6):
                    tmp[j] = y[j] + dt * k3[j]
                rhs(tmp, p, consts, k4)
                for j in range(6):
                    y[j] = y[j] + dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
            out[i] = y
        return out

    _NUMBA["rk4"] = rk4
    return rk4


def entry_field_components(s, p, consts, sqrt, exp):
    """`entry_rhs` written on components with the given ``sqrt`` and ``exp``: heyoka
    expressions (`heyoka_entry_rhs`) or JAX arrays of one component each (the component-wise
    gnc_jax variant, `_entry_arc_components`). Returns d/dt s as a 6-tuple."""
    x, y, z, vx, vy, vz = s
    kd, kl, cb, sb = p
    mu, re, j2, w, scale_height = consts
    r2 = x * x + y * y + z * z
    r = sqrt(r2)
    sin_lat = z / r
    mu_r2 = mu / r2
    j2_term = j2 * re * re / r2
    g_r = -mu_r2 * (1.0 + 1.5 * j2_term * (1.0 - 5.0 * sin_lat * sin_lat))
    g_z = -3.0 * mu_r2 * j2_term * sin_lat
    u = (x / r, y / r, z / r)
    a = (vx + w * y, vy - w * x, vz)
    speed = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    rho_n = exp(-(r - re) / scale_height)
    drag = kd * rho_n * speed
    lift = kl * rho_n * speed * speed
    h = tuple(c / speed for c in a)
    d = u[0] * h[0] + u[1] * h[1] + u[2] * h[2]
    up = tuple(u[i] - d * h[i] for i in range(3))
    norm = sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2])
    up = tuple(c / norm for c in up)
    right = (
        h[1] * up[2] - h[2] * up[1],
        h[2] * up[0] - h[0] * up[2],
        h[0] * up[1] - h[1] * up[0],
    )
    acc = [g_r * u[i] - drag * a[i] + lift * (cb * up[i] + sb * right[i]) for i in range(3)]
    return (vx, vy, vz, acc[0], acc[1], acc[2] + g_z)


def heyoka_entry_rhs(consts):
    """``(variables, right-hand sides)`` of `entry_rhs` in heyoka's expression system; the
    params are ``par[0..3]``."""
    import heyoka as hy

    variables = hy.make_vars("x", "y", "z", "vx", "vy", "vz")
    pars = [hy.par[i] for i in range(4)]
    consts = [float(c) for c in consts]
    return variables, list(entry_field_components(variables, pars, consts, hy.sqrt, hy.exp))


def _entry_arc_components(consts, item, dt, n_steps, tableau):
    """gnc_jax's fixed-step scan of `entry_field_components` on JAX scalars: under ``vmap``
    every component is a contiguous batch array (structure of arrays), where the package's
    field works on (batch, 3) vectors."""
    state, params = item
    consts = tuple(consts[i] for i in range(5))

    def field(t, y, p):
        return entry_field_components(y, p, consts, jnp.sqrt, jnp.exp)

    y = integrate_fixed(field, 0.0, tuple(state), dt, n_steps, tuple(params), tableau=tableau)
    return jnp.stack(y)


# --------------------------------------------------------------------------------------------
# Heliocentric: the problem and its transcriptions


class CruiseEnsemble(NamedTuple):
    model: HeliocentricModel  # as the midcourse system builds it (ephemeris table)
    t0_s: float
    t1_s: float
    states: np.ndarray  # (n, 6)


def cruise_ensemble(n: int, seed: int = 0) -> CruiseEnsemble:
    """``n`` dispersed states at the ``phoenix-midcourse`` first fix, propagated to E-10 d."""
    from gnc_jax.geometry.kepler import propagate_kepler
    from gnc_jax.geometry.lambert import solve_lambert
    from gnc_jax.systems.midcourse.build import simulation_data
    from gnc_jax.systems.midcourse.params import parameters

    scenario = gj.load_scenario("phoenix-midcourse")
    p = parameters(scenario.config)
    sim = simulation_data(p)  # model and epochs, no nominal design
    launch = p.mission.launch_epoch_s
    t_fix, t_enc = float(sim.t_first_fix_s), float(sim.t_encounter_s)
    r_earth, _ = ephemeris.planet_state(ephemeris.planet_index("earth"), launch)
    r_mars, _ = ephemeris.planet_state(sim.model.target, t_enc)
    v1, _ = solve_lambert(r_earth, r_mars, t_enc - launch, ephemeris.GM_SUN)
    r0, v0 = propagate_kepler(r_earth, v1, t_fix - launch, ephemeris.GM_SUN)
    rng = np.random.default_rng(seed)
    err = sim.errors
    dr = float(err.position_m) * rng.standard_normal((n, 3))
    dv = float(err.velocity_mps) * rng.standard_normal((n, 3))
    states = np.concatenate([np.asarray(r0) + dr, np.asarray(v0) + dv], axis=1)
    return CruiseEnsemble(sim.model, t_fix, t_enc - CRUISE_END_BEFORE_ENCOUNTER_S, states)


def _heyoka_plan94(index, t_millennia):
    """Heliocentric EME2000 position (m) of planet ``index``: `ephemeris.planet_state`'s
    equations (Simon et al. 1994 mean elements, plan94) as heyoka expressions of time."""
    import heyoka as hy

    e_ = ephemeris
    t = t_millennia

    def polynomial(table):
        c = table[index]
        return c[0] + (c[1] + c[2] * t) * t

    def angle(table):
        c = table[index]
        return (3600.0 * c[0] + (c[1] + c[2] * t) * t) * e_._ARCSEC_TO_RAD

    def periodic(cos_table, sin_table, frequency_table, n_pure):
        pure, poisson = [], []
        for k in range(cos_table.shape[1]):
            f, c, s = (float(tab[index, k]) for tab in (frequency_table, cos_table, sin_table))
            if c == 0.0 and s == 0.0:
                continue
            if f == 0.0:  # cos(0) = 1: a constant term
                term = hy.expression(c)
            else:
                argument = (f * e_._PERIODIC_RATE) * t
                term = c * hy.cos(argument) + s * hy.sin(argument)
            (pure if k < n_pure else poisson).append(term)
        total = hy.sum(pure) if pure else hy.expression(0.0)
        if poisson:
            total = total + t * hy.sum(poisson)
        return total * 1e-7

    a = polynomial(e_._A) + periodic(e_._A_COS, e_._A_SIN, e_._A_FREQUENCY, e_._N_PERIODIC_A)
    mean_longitude = angle(e_._MEAN_LONGITUDE) + periodic(
        e_._L_COS, e_._L_SIN, e_._L_FREQUENCY, e_._N_PERIODIC_L
    )
    e = polynomial(e_._ECCENTRICITY)
    perihelion = angle(e_._PERIHELION_LONGITUDE)
    inclination = angle(e_._INCLINATION)
    node = angle(e_._NODE_LONGITUDE)
    ecc_anomaly = hy.kepE(e, mean_longitude - perihelion)
    cos_e, sin_e = hy.cos(ecc_anomaly), hy.sin(ecc_anomaly)
    one_minus = 1.0 - e * cos_e
    # cos and sin of the true anomaly from the eccentric one, then of the true longitude
    cos_nu = (cos_e - e) / one_minus
    sin_nu = hy.sqrt(1.0 - e * e) * sin_e / one_minus
    cos_w, sin_w = hy.cos(perihelion), hy.sin(perihelion)
    cos_l = cos_nu * cos_w - sin_nu * sin_w
    sin_l = sin_nu * cos_w + cos_nu * sin_w
    radius = a * one_minus
    sin_half_i = hy.sin(0.5 * inclination)
    q = sin_half_i * hy.cos(node)
    p = sin_half_i * hy.sin(node)
    out_of_plane = 2.0 * (p * cos_l - q * sin_l)
    ecliptic = (
        radius * (cos_l - out_of_plane * p),
        radius * (sin_l + out_of_plane * q),
        -radius * out_of_plane * hy.cos(0.5 * inclination),
    )
    rot = e_.ECLIPTIC_TO_EQUATORIAL
    return [
        e_.AU_M * sum(float(rot[j, k]) * ecliptic[k] for k in range(3) if rot[j, k] != 0.0)
        for j in range(3)
    ]


def heyoka_cruise_rhs(model: HeliocentricModel):
    """``(variables, right-hand sides)`` of `heliocentric.vector_field` (plan94 planets) in
    heyoka's expression system; time is ``hy.time`` in seconds past J2000 TDB."""
    import heyoka as hy

    x, y, z, vx, vy, vz = hy.make_vars("x", "y", "z", "vx", "vy", "vz")
    t_millennia = hy.time / (ephemeris.SECONDS_PER_DAY * ephemeris._DAYS_PER_MILLENNIUM)
    srp = float(model.srp_m2_per_kg * model.solar_pressure_npm2) * ephemeris.AU_M**2
    central = srp - float(model.gm_sun)
    r2 = x * x + y * y + z * z
    r3 = r2 * hy.sqrt(r2)
    acc = [central * c / r3 for c in (x, y, z)]
    for i, mu in enumerate(np.asarray(model.gm_planets, dtype=float)):
        if mu == 0.0:
            continue
        rp = _heyoka_plan94(i, t_millennia)
        d = [rp[0] - x, rp[1] - y, rp[2] - z]
        d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        d3 = d2 * hy.sqrt(d2)
        p2 = rp[0] * rp[0] + rp[1] * rp[1] + rp[2] * rp[2]
        p3 = p2 * hy.sqrt(p2)
        acc = [acc[j] + float(mu) * (d[j] / d3 - rp[j] / p3) for j in range(3)]
    return [x, y, z, vx, vy, vz], [vx, vy, vz, *acc]


def erfa_cruise_rhs(model: HeliocentricModel):
    """``f(t, y)`` of the same force model for scipy, the planets from ERFA's ``plan94``."""
    import erfa

    srp = float(model.srp_m2_per_kg * model.solar_pressure_npm2) * ephemeris.AU_M**2
    central = srp - float(model.gm_sun)
    gm = np.asarray(model.gm_planets, dtype=float)[:, None]
    numbers = np.arange(1, 9)

    def f(t, y):
        pv = erfa.plan94(2451545.0, t / DAY_S, numbers)  # J2000 TDB + days; au, EME2000
        rp = pv["p"] * ephemeris.AU_M
        r = y[:3]
        d = rp - r
        dn = np.sqrt(np.sum(d * d, axis=1, keepdims=True))
        pn = np.sqrt(np.sum(rp * rp, axis=1, keepdims=True))
        a = central * r / np.dot(r, r) ** 1.5 + np.sum(gm * (d / dn**3 - rp / pn**3), axis=0)
        return np.concatenate([y[3:], a])

    return f


# --------------------------------------------------------------------------------------------
# heyoka ensembles


def heyoka_integrator(variables, rhs, tol, n_pars=0, high_accuracy=False, compact_mode=False):
    """``(integrator, compile_s)``: a batch-mode Taylor integrator of the recommended SIMD
    width (8 doubles with AVX-512)."""
    import heyoka as hy

    width = hy.recommended_simd_size()
    kwargs = dict(tol=tol, high_accuracy=high_accuracy, compact_mode=compact_mode)
    if n_pars:
        kwargs["pars"] = np.zeros((n_pars, width))
    # Cold compilation, as gnc_jax's is timed: heyoka keeps compiled code in an in-process
    # cache and an on-disk cache (~/.cache/heyoka) that would turn a rerun into a lookup.
    llvm = hy.llvm_state
    disk = llvm.get_diskcache_enabled()
    llvm.set_diskcache_enabled(False)
    llvm.clear_memcache()
    try:
        t0 = time.perf_counter()
        ta = hy.taylor_adaptive_batch(list(zip(variables, rhs)), np.zeros((6, width)), **kwargs)
        return ta, time.perf_counter() - t0
    finally:
        llvm.set_diskcache_enabled(disk)


def _padded(array, width):
    if array is None:
        return None
    pad = -len(array) % width
    return np.concatenate([array, np.repeat(array[-1:], pad, axis=0)])


def heyoka_ensemble(pool, states, t0, t1, params=None):
    """Propagate every row of ``states`` from ``t0`` to ``t1`` with a pool of batch
    integrators, one per thread, each taking every ``len(pool)``-th batch of arcs (state,
    time and parameters reset, then ``propagate_until``; heyoka releases the GIL while it
    integrates). Returns ``(finals (n, 6), lane steps (n,), executed steps (n,))``: a batch
    steps until its slowest lane is done, so each arc pays its batch's largest step count."""
    import heyoka as hy

    width = pool[0].batch_size
    n = len(states)
    states_p, params_p = _padded(states, width), _padded(params, width)
    n_batches = len(states_p) // width
    finals = np.empty_like(states_p)
    lane_steps = np.empty(len(states_p))
    executed = np.empty(len(states_p))

    def work(k):
        ta = pool[k]
        for b in range(k, n_batches, len(pool)):
            rows = slice(b * width, (b + 1) * width)
            ta.set_time(np.full(width, float(t0)))
            ta.state[:] = states_p[rows].T
            if params_p is not None:
                ta.pars[:] = params_p[rows].T
            ta.propagate_until(float(t1))
            result = ta.propagate_res
            if any(lane[0] != hy.taylor_outcome.time_limit for lane in result):
                raise RuntimeError(f"heyoka: an arc of batch {b} stopped early: {result}")
            finals[rows] = ta.state.T
            lane_steps[rows] = [lane[3] for lane in result]
            executed[rows] = max(lane[3] for lane in result)

    with ThreadPoolExecutor(len(pool)) as executor:
        list(executor.map(work, range(len(pool))))
    return finals[:n], lane_steps[:n], executed[:n]


def heyoka_ensemble_api(ta, states, t0, t1, params=None):
    """The same with ``heyoka.ensemble_propagate_until_batch`` (one task per batch of arcs,
    each on a deep copy of ``ta``): the documented ensemble interface. Returns the finals."""
    import heyoka as hy

    width = ta.batch_size
    states_p, params_p = _padded(states, width), _padded(params, width)

    def gen(local, i):
        local.set_time(np.full(width, float(t0)))
        local.state[:] = states_p[i * width : (i + 1) * width].T
        if params_p is not None:
            local.pars[:] = params_p[i * width : (i + 1) * width].T
        return local

    results = hy.ensemble_propagate_until_batch(ta, float(t1), len(states_p) // width, gen)
    return np.concatenate([res[0].state.T for res in results])[: len(states)]


def _heyoka_rows(
    variables, rhs, tols, states, t0, t1, repeats, cores, check, ref, params=None, **kw
):
    """One row per tolerance, all cores; each row keeps a one-core re-timing closure."""
    import copy

    rows = []
    for tol in tols:
        n_pars = 0 if params is None else params.shape[1]
        ta, compile_s = heyoka_integrator(variables, rhs, tol, n_pars=n_pars, **kw)
        pool = [ta] + [copy.deepcopy(ta) for _ in range(cores - 1)]
        finals, lane, executed = heyoka_ensemble(pool, states, t0, t1, params)
        wall = min(
            _timed(lambda pool=pool: heyoka_ensemble(pool, states, t0, t1, params))
            for _ in range(repeats)
        )
        row = dict(
            tool="heyoka",
            method=f"taylor batch {ta.batch_size}, order {ta.order}",
            setting=f"tol {tol:g}",
            compile_s=compile_s,
            wall_s=wall,
            steps_per_arc=float(lane.mean()),
            executed_steps_per_arc=float(executed.mean()),
            order=ta.order,
        )
        row["_one_core"] = lambda pool=pool: min(
            _timed(lambda: heyoka_ensemble(pool[:1], states, t0, t1, params))
            for _ in range(max(repeats, 5))
        )
        row["_integrator"] = ta
        rows.append(_finish(row, len(states), None, _position_errors(finals[check], ref)))
    return rows


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


# --------------------------------------------------------------------------------------------
# gnc_jax rows


def _gnc_row(one, shared, batch, repeats, check, ref, evals_per_arc, **fields):
    """Time ``one(shared, item)`` vmapped over ``batch`` on all devices; the row keeps a
    closure that re-times it vmapped on one device (one core)."""
    fn = _sharded(one)
    out, compile_s, wall = _compile_and_time(fn, shared, batch, repeats)
    final = out[0] if isinstance(out, tuple) else out
    if isinstance(final, EntryState):
        final = np.concatenate([np.asarray(final.r), np.asarray(final.v)], axis=1)
    n_arcs = len(np.asarray(final))
    row = dict(tool="gnc_jax", compile_s=compile_s, wall_s=wall, **fields)
    if callable(evals_per_arc):  # adaptive: from the step counts
        evals_per_arc = evals_per_arc(out)
        row["steps_per_arc"] = float(np.mean(np.asarray(out[1])))

    def one_core():
        device = jax.devices()[0]
        single = jax.jit(jax.vmap(one, in_axes=(None, 0)))
        args = jax.device_put((shared, batch), device)
        compiled = single.lower(*args).compile()
        jax.block_until_ready(compiled(*args))
        return _best_of(lambda: compiled(*args), max(repeats, 5))

    row["_one_core"] = one_core
    return _finish(row, n_arcs, evals_per_arc, _position_errors(np.asarray(final)[check], ref))


def _bare_rhs_ns(fn, shared, batch, repeats):
    """ns per right-hand-side evaluation of ``fn(shared, item)`` vmapped over ``batch`` on one
    device."""
    device = jax.devices()[0]
    args = jax.device_put((shared, batch), device)
    compiled = jax.jit(jax.vmap(fn, in_axes=(None, 0))).lower(*args).compile()
    jax.block_until_ready(compiled(*args))
    n = len(jax.tree_util.tree_leaves(batch)[0])
    return 1e9 * _best_of(lambda: compiled(*args), repeats) / n


def _heyoka_cfunc_ns(variables, rhs, inputs, repeats, pars=None, times=None):
    """ns per right-hand-side evaluation of heyoka's compiled function (``cfunc``) over the
    columns of ``inputs``, one thread."""
    import heyoka as hy

    cf = hy.cfunc(rhs, vars=variables)
    kwargs = {}
    if pars is not None:
        kwargs["pars"] = pars
    if times is not None:
        kwargs["time"] = times
    outputs = np.empty_like(inputs)
    threads = hy.get_nthreads()
    hy.set_nthreads(1)
    try:
        cf(inputs, outputs=outputs, **kwargs)
        wall = min(_timed(lambda: cf(inputs, outputs=outputs, **kwargs)) for _ in range(repeats))
    finally:
        hy.set_nthreads(threads)
    return 1e9 * wall / inputs.shape[1]


# --------------------------------------------------------------------------------------------
# The benchmarks


def _finish(row, n_arcs, evals_per_arc, errors):
    """Fill the derived columns of a row."""
    row["arcs"] = n_arcs
    row["arcs_per_s"] = n_arcs / row["wall_s"]
    if evals_per_arc is not None:
        row["rhs_per_arc"] = float(evals_per_arc)
        row["rhs_per_s"] = row["arcs_per_s"] * evals_per_arc
    row["error_max_m"] = float(np.max(errors))
    row["error_median_m"] = float(np.median(errors))
    return row


def _have(module):
    try:
        __import__(module)
        return True
    except ImportError:
        return False


def entry_benchmark(quick, n_arcs, repeats, cores):
    """Rows, bare RHS costs and notes of the entry ensemble (see the module docstring)."""
    from scipy.integrate import solve_ivp

    n_check = 4 if quick else 24
    ens = entry_ensemble(n_arcs)
    check = np.arange(n_check)
    rows, bare = [], {}

    def scipy_arc(i, rtol):
        p, c, out = ens.params[i], ens.consts, np.empty(6)

        def f(t, s):
            entry_rhs(s, p, c, out)
            return out.copy()

        sol = solve_ivp(f, (0.0, ENTRY_ARC_S), ens.states[i], "DOP853", rtol=rtol, atol=1e-9)
        return sol.y[:, -1], sol.nfev, len(sol.t) - 1

    t0 = time.perf_counter()
    ref = np.array([scipy_arc(i, 1e-13)[0] for i in check])
    ref_s = time.perf_counter() - t0

    # gnc_jax: fixed-step scans, vmapped and sharded
    grid = {RK4: (1.0, 2.0, 4.0, 8.0, 16.0), RK6_BUTCHER: (4.0, 8.0, 16.0, 32.0)}
    if quick:
        grid = {RK4: (4.0, 8.0), RK6_BUTCHER: (16.0,)}
    for tableau, steps in grid.items():
        for dt in steps:
            n = int(round(ENTRY_ARC_S / dt))
            one = lambda e, item, dt=dt, n=n, tab=tableau: _entry_arc(e, item, dt, n, tab)  # noqa: E731
            rows.append(
                _gnc_row(
                    one,
                    ens.earth,
                    ens.batch,
                    repeats,
                    check,
                    ref,
                    n * tableau.stages,
                    method=f"{tableau.name} scan",
                    setting=f"dt {dt:g} s",
                    steps_per_arc=n,
                )
            )
    if not quick:  # the package's default US76 table: cost only (other equations)
        us76 = entry_ensemble(n_arcs, model="us76")
        dt, n = 2.0, int(round(ENTRY_ARC_S / 2.0))
        fn = _sharded(lambda e, item: _entry_arc(e, item, dt, n, RK4))
        _, compile_s, wall = _compile_and_time(fn, us76.earth, us76.batch, repeats)
        rows.append(
            dict(
                tool="gnc_jax",
                method="rk4 scan, US76 table (cost only)",
                setting=f"dt {dt:g} s",
                compile_s=compile_s,
                wall_s=wall,
                steps_per_arc=n,
                arcs=n_arcs,
                arcs_per_s=n_arcs / wall,
                rhs_per_arc=4.0 * n,
                rhs_per_s=4 * n * n_arcs / wall,
            )
        )
    tiled = jax.tree_util.tree_map(lambda x: jnp.tile(x, (64,) + (1,) * (x.ndim - 1)), ens.batch)

    def field(e, item):
        y, vehicle, atmosphere, bank = item
        return entry_vector_field(0.0, y, EntryArgs(vehicle, e, atmosphere, bank))

    bare["gnc_jax"] = _bare_rhs_ns(field, ens.earth, tiled, repeats)

    # the same equations on components (structure of arrays under vmap): not the package's
    # field, a measure of what its (batch, 3) layout costs
    consts, items = jnp.asarray(ens.consts), (jnp.asarray(ens.states), jnp.asarray(ens.params))
    grid = {RK4: (2.0, 4.0, 8.0, 16.0), RK6_BUTCHER: (8.0, 16.0)}
    if quick:
        grid = {RK4: (8.0,)}
    for tableau, steps in grid.items():
        for dt in steps:
            n = int(round(ENTRY_ARC_S / dt))
            one = lambda c, item, dt=dt, n=n, tab=tableau: _entry_arc_components(
                c, item, dt, n, tab
            )  # noqa: E731
            row = _gnc_row(
                one,
                consts,
                items,
                repeats,
                check,
                ref,
                n * tableau.stages,
                method=f"{tableau.name} scan, component-wise field",
                setting=f"dt {dt:g} s",
                steps_per_arc=n,
            )
            row["tool"] = COMPONENTS
            rows.append(row)

    if _have("heyoka"):
        variables, rhs = heyoka_entry_rhs(ens.consts)
        tols = (1e-6, 1e-8) if quick else (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-12)
        rows += _heyoka_rows(
            variables,
            rhs,
            tols,
            ens.states,
            0.0,
            ENTRY_ARC_S,
            repeats,
            cores,
            check,
            ref,
            params=ens.params,
        )
        inputs = np.ascontiguousarray(np.tile(ens.states.T, (1, 64)))
        pars = np.ascontiguousarray(np.tile(ens.params.T, (1, 64)))
        bare["heyoka"] = _heyoka_cfunc_ns(variables, rhs, inputs, repeats, pars=pars)
        if not quick:
            ta, _ = heyoka_integrator(variables, rhs, 1e-8, n_pars=4)
            final = heyoka_ensemble_api(ta, ens.states, 0.0, ENTRY_ARC_S, ens.params)
            wall = min(
                _timed(lambda: heyoka_ensemble_api(ta, ens.states, 0.0, ENTRY_ARC_S, ens.params))
                for _ in range(repeats)
            )
            rows.append(
                _finish(
                    dict(
                        tool="heyoka (ensemble API)",
                        method="ensemble_propagate_until_batch",
                        setting="tol 1e-08",
                        compile_s=0.0,
                        wall_s=wall,
                    ),
                    n_arcs,
                    None,
                    _position_errors(final[check], ref),
                )
            )

    if _have("numba"):
        rk4 = numba_entry_rk4()
        t0 = time.perf_counter()
        rk4(ens.states[:2], ens.params[:2], ens.consts, 1.0, 1)
        compile_s = time.perf_counter() - t0
        for dt in (4.0, 8.0) if quick else (1.0, 2.0, 4.0, 8.0, 16.0):
            n = int(round(ENTRY_ARC_S / dt))
            run = lambda dt=dt, n=n: rk4(ens.states, ens.params, ens.consts, dt, n)  # noqa: E731
            final = run()
            wall = min(_timed(run) for _ in range(repeats))
            row = dict(
                tool="numba",
                method="rk4, prange",
                setting=f"dt {dt:g} s",
                compile_s=compile_s,
                wall_s=wall,
                steps_per_arc=n,
            )
            rows.append(_finish(row, n_arcs, 4 * n, _position_errors(final[check], ref)))
        bare["numba"] = _numba_bare_ns(ens, repeats)

    n_loop = 2 if quick else 8
    for rtol in (1e-7,) if quick else (1e-6, 1e-7, 1e-9):
        t0 = time.perf_counter()
        outs = [scipy_arc(i, rtol) for i in range(n_loop)]
        wall = time.perf_counter() - t0
        final = np.array([o[0] for o in outs])
        m = min(n_loop, n_check)
        row = dict(
            tool="scipy",
            method="solve_ivp DOP853 loop",
            setting=f"rtol {rtol:g}",
            compile_s=0.0,
            wall_s=wall,
            steps_per_arc=float(np.mean([o[2] for o in outs])),
        )
        rows.append(
            _finish(
                row, n_loop, np.mean([o[1] for o in outs]), _position_errors(final[:m], ref[:m])
            )
        )
    for r in rows:
        r["problem"] = "entry"
    notes = [
        f"entry: {n_arcs} arcs of {ENTRY_ARC_S:.0f} s from the lunar-skip-entry interface "
        f"(scenario dispersions), bank U({ENTRY_BANK_DEG[0]:g}, {ENTRY_BANK_DEG[1]:g}) deg, the "
        f"package's exponential atmosphere on every side (US76 is a 1000-node table heyoka "
        f"cannot express; the US76 row shows its cost in gnc_jax); errors over {n_check} arcs "
        f"against scipy DOP853 rtol 1e-13 with a plain-Python field ({ref_s:.1f} s); scipy "
        f"rows over the first {n_loop} arcs",
    ]
    return rows, bare, notes


def _numba_bare_ns(ens, repeats):
    """ns per evaluation of the numba field in a plain loop, one thread."""
    import numba

    rhs = numba.njit(entry_rhs)

    @numba.njit
    def loop(states, params, consts, reps):
        out = np.empty(6)
        total = 0.0
        for _ in range(reps):
            for i in range(states.shape[0]):
                rhs(states[i], params[i], consts, out)
                total += out[3]
        return total

    loop(ens.states, ens.params, ens.consts, 1)
    wall = min(_timed(lambda: loop(ens.states, ens.params, ens.consts, 64)) for _ in range(repeats))
    return 1e9 * wall / (64 * len(ens.states))


def _cruise_arc(model, x0, t0, dt, n, tableau):
    return integrate_fixed(vector_field, t0, x0, dt, n, model, tableau=tableau)


def _adaptive_arc(model, x0, t0, t1):
    from gnc_jax.dynamics.heliocentric import _solve  # what `propagate` runs, with its stats

    sol = _solve(model, vector_field, jnp.asarray(t0), jnp.asarray(t1), x0)
    return sol.ys[-1], sol.stats["num_steps"]


def cruise_benchmark(quick, n_arcs, repeats, cores):
    """Rows, bare RHS costs and notes of the heliocentric ensemble (module docstring)."""
    import diffrax

    n_check = 4 if quick else 16
    ens = cruise_ensemble(n_arcs)
    check = np.arange(n_check)
    t0, t1, span = ens.t0_s, ens.t1_s, ens.t1_s - ens.t0_s
    batch = jnp.asarray(ens.states)
    rows, bare = [], {}
    no_table = lambda m: eqx.tree_at(lambda x: x.ephemeris, m, None)  # noqa: E731

    t_ = time.perf_counter()
    if _have("heyoka"):
        variables, rhs = heyoka_cruise_rhs(ens.model)
        ta, _ = heyoka_integrator(variables, rhs, 1e-15, high_accuracy=True, compact_mode=True)
        ref, _, _ = heyoka_ensemble([ta], ens.states[check], t0, t1)
        ref_note = "heyoka tol 1e-15 in high-accuracy mode"
    else:
        tight = no_table(eqx.tree_at(lambda m: m.rtol, ens.model, jnp.asarray(1e-14)))
        fn = jax.jit(jax.vmap(_adaptive_arc, in_axes=(None, 0, None, None)))
        ref = np.asarray(fn(tight, batch[check], t0, t1)[0])
        ref_note = "gnc_jax Dopri8 rtol 1e-14 with plan94 direct (heyoka not installed)"
    ref_note += f" ({time.perf_counter() - t_:.1f} s)"

    new_evals = diffrax.Dopri8.tableau.c.shape[0]  # per step: 14 stages, first same as last
    variants = [("table", 1e-13), ("table", 1e-11), ("table", 1e-9), ("plan94 direct", 1e-13)]
    if quick:
        variants = [("table", 1e-13)]
    for ephem, rtol in variants:
        model = eqx.tree_at(lambda m: m.rtol, ens.model, jnp.asarray(rtol))
        model = model if ephem == "table" else no_table(model)
        midcourse = " (midcourse)" if ephem == "table" and rtol == 1e-13 else ""
        rows.append(
            _gnc_row(
                lambda m, x: _adaptive_arc(m, x, t0, t1),
                model,
                batch,
                repeats,
                check,
                ref,
                lambda out: new_evals * float(np.mean(np.asarray(out[1]))) + 1,
                method=f"dopri8 adaptive, {ephem}",
                setting=f"rtol {rtol:g}{midcourse}",
            )
        )
    grid = {RK4: (0.125, 0.25, 0.5), RK6_BUTCHER: (0.25, 0.5, 1.0)}
    if quick:
        grid = {RK6_BUTCHER: (0.5,)}
    for tableau, steps in grid.items():
        for dt_days in steps:
            n = int(round(span / (dt_days * DAY_S)))
            one = lambda m, x, n=n, tab=tableau: _cruise_arc(m, x, t0, span / n, n, tab)  # noqa: E731
            rows.append(
                _gnc_row(
                    one,
                    ens.model,
                    batch,
                    repeats,
                    check,
                    ref,
                    n * tableau.stages,
                    method=f"{tableau.name} scan, table",
                    setting=f"dt {dt_days:g} d",
                    steps_per_arc=n,
                )
            )
    times = np.full(64 * n_arcs, t0 + 0.5 * span)  # one epoch, as the batch in a scan
    tiled = jnp.tile(batch, (64, 1))
    bare["gnc_jax"] = _bare_rhs_ns(
        lambda m, item: vector_field(item[0], item[1], m),
        ens.model,
        (jnp.asarray(times), tiled),
        repeats,
    )

    if _have("heyoka"):
        tols = (1e-12,) if quick else (1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14)
        rows += _heyoka_rows(
            variables, rhs, tols, ens.states, t0, t1, repeats, cores, check, ref, compact_mode=True
        )
        bare["heyoka"] = _heyoka_cfunc_ns(
            variables, rhs, np.ascontiguousarray(np.asarray(tiled).T), repeats, times=times
        )

    if _have("erfa"):
        from scipy.integrate import solve_ivp

        f = erfa_cruise_rhs(ens.model)
        n_loop = 2 if quick else 8
        for rtol in (1e-10,) if quick else (1e-10, 1e-13):
            t_ = time.perf_counter()
            sols = [
                solve_ivp(f, (t0, t1), ens.states[i], "DOP853", rtol=rtol, atol=1e-9)
                for i in range(n_loop)
            ]
            wall = time.perf_counter() - t_
            final = np.array([s.y[:, -1] for s in sols])
            m = min(n_loop, n_check)
            row = dict(
                tool="scipy",
                method="solve_ivp DOP853 loop, ERFA plan94",
                setting=f"rtol {rtol:g}",
                compile_s=0.0,
                wall_s=wall,
                steps_per_arc=float(np.mean([len(s.t) - 1 for s in sols])),
            )
            rows.append(
                _finish(
                    row,
                    n_loop,
                    np.mean([s.nfev for s in sols]),
                    _position_errors(final[:m], ref[:m]),
                )
            )
    for r in rows:
        r["problem"] = "cruise"
    notes = [
        f"cruise: {n_arcs} arcs of {span / DAY_S:.0f} d (phoenix-midcourse first fix to E-10 d) "
        "around the scenario's Lambert conic, Sun + 8 planets (plan94) + radiation pressure; "
        f"errors over {n_check} arcs against {ref_note}; 'table' rows take the planets from "
        "the quintic Hermite table as the midcourse system does (interpolation error < 1 cm, "
        "8 m for Mercury), 'plan94 direct' and heyoka evaluate plan94 itself",
    ]
    return rows, bare, notes


# --------------------------------------------------------------------------------------------
# Summary: equal accuracy, ratios and the profile of the gap


def _fastest(rows, tool, limit_m, method_contains=""):
    """The fastest row of ``tool`` whose worst checked error is within ``limit_m``."""
    ok = [
        r
        for r in rows
        if r["tool"] == tool
        and r.get("error_max_m", math.inf) <= limit_m
        and method_contains in r["method"]
    ]
    return max(ok, key=lambda r: r["arcs_per_s"]) if ok else None


def _label(row):
    return f"{row['tool']} {row['method']}, {row['setting']}"


def summarise(rows, problem, requirements, bare, cores, one_core=True):
    """Summary and profile rows and notes of one problem: at each accuracy requirement the
    fastest gnc_jax setting against the fastest of each peer; at the first requirement a
    per-core profile of gnc_jax against heyoka."""
    mine = [r for r in rows if r["problem"] == problem]
    out, notes = [], []
    for limit in requirements:
        g = _fastest(mine, "gnc_jax", limit)
        h = _fastest(mine, "heyoka", limit)
        comparisons = [(g, _fastest(mine, tool, limit)) for tool in ("heyoka", "numba", "scipy")]
        comparisons.append((_fastest(mine, COMPONENTS, limit), h))
        if problem == "cruise":  # heyoka's exact equations
            comparisons.append((_fastest(mine, "gnc_jax", limit, "plan94"), h))
        for a, b in comparisons:
            if a is None or b is None:
                continue
            ratio = a["arcs_per_s"] / b["arcs_per_s"]
            out.append(
                dict(
                    problem=problem,
                    tool="summary",
                    requirement_m=limit,
                    method=f"{a['tool']} / {b['tool']}",
                    setting=f"{_label(a)} vs {_label(b)}",
                    ratio=ratio,
                    error_max_m=a["error_max_m"],
                    peer_error_max_m=b["error_max_m"],
                )
            )
            notes.append(
                f"{problem}, worst error <= {limit:g} m: {_label(a)} {a['arcs_per_s']:,.0f} "
                f"arcs/s ({a['error_max_m']:.2g} m) vs {_label(b)} {b['arcs_per_s']:,.0f} "
                f"arcs/s ({b['error_max_m']:.2g} m): ratio {ratio:.3g}"
            )
        if limit == requirements[0] and g is not None and h is not None:
            p = profile(g, h, _fastest(mine, COMPONENTS, limit), bare, cores, one_core)
            p.update(
                problem=problem,
                tool="profile",
                method="gnc_jax vs heyoka, per core",
                setting=f"{_label(g)} vs {_label(h)}",
                requirement_m=limit,
            )
            out.append(p)
            notes.append(_profile_note(problem, p, bare))
    return out, notes


def profile(g, h, c, bare, cores, one_core=True):
    """Per-core decomposition of the gnc_jax / heyoka gap: time per arc = evaluations per arc
    x ns per evaluation, a Taylor step counted in heyoka's own RHS evaluations (its compiled
    field, ``cfunc``). With ``one_core`` each row is re-timed on one core; otherwise its core
    time is the all-core wall time x the cores (no recompilation; equal on a quiet machine).
    ``c`` is the component-wise gnc_jax row (or None)."""

    def seconds_per_arc(row):
        if one_core:
            return row["_one_core"]() / row["arcs"]
        return row["wall_s"] * cores / row["arcs"]

    g_s, h_s = seconds_per_arc(g), seconds_per_arc(h)
    g_ns = 1e9 * g_s / g["rhs_per_arc"]
    h_step_us = 1e6 * h_s / h["executed_steps_per_arc"]
    h_evals_per_step = 1e3 * h_step_us / bare["heyoka"]
    h_evals = h_evals_per_step * h["executed_steps_per_arc"]
    out = dict(
        gnc_jax_arcs_per_s_per_core=1.0 / g_s,
        heyoka_arcs_per_s_per_core=1.0 / h_s,
        heyoka_over_gnc_jax=g_s / h_s,
        gnc_jax_steps_per_arc=g["steps_per_arc"],
        gnc_jax_rhs_per_arc=g["rhs_per_arc"],
        gnc_jax_ns_per_rhs=g_ns,
        gnc_jax_bare_ns_per_rhs=bare["gnc_jax"],
        heyoka_steps_per_arc=h["executed_steps_per_arc"],
        heyoka_order=h["order"],
        heyoka_us_per_step=h_step_us,
        heyoka_ns_per_rhs=bare["heyoka"],
        heyoka_rhs_per_step=h_evals_per_step,
        heyoka_rhs_per_arc=h_evals,
        evaluations_factor=g["rhs_per_arc"] / h_evals,
        cost_factor=g_ns / bare["heyoka"],
    )
    if c is not None:
        c_s = seconds_per_arc(c)
        out.update(
            components_ns_per_rhs=1e9 * c_s / c["rhs_per_arc"], heyoka_over_components=c_s / h_s
        )
    return out


def _profile_note(problem, p, bare):
    note = (
        f"{problem} profile, per core: gnc_jax {p['gnc_jax_rhs_per_arc']:,.0f} RHS per arc at "
        f"{p['gnc_jax_ns_per_rhs']:.0f} ns (the bare vmapped field: "
        f"{p['gnc_jax_bare_ns_per_rhs']:.0f} ns); heyoka {p['heyoka_steps_per_arc']:.1f} Taylor "
        f"steps (its batches' slowest lanes) of order {p['heyoka_order']} at "
        f"{p['heyoka_us_per_step']:.2f} us = {p['heyoka_rhs_per_step']:.0f} of its own RHS "
        f"evaluations ({p['heyoka_ns_per_rhs']:.1f} ns each, compiled cfunc), "
        f"{p['heyoka_rhs_per_arc']:,.0f} per arc. Speed ratio heyoka/gnc_jax per core "
        f"{p['heyoka_over_gnc_jax']:.3g} = evaluations per arc {p['evaluations_factor']:.3g} x "
        f"cost per evaluation {p['cost_factor']:.3g}"
    )
    if "components_ns_per_rhs" in p:
        note += (
            f"; the component-wise field costs {p['components_ns_per_rhs']:.0f} ns per RHS "
            f"(heyoka/it {p['heyoka_over_components']:.3g})"
        )
    if "numba" in bare:
        note += f"; numba's field {bare['numba']:.0f} ns per RHS"
    return note


COLUMNS = (
    ("tool", "tool", "{}"),
    ("method", "method", "{}"),
    ("setting", "setting", "{}"),
    ("arcs", "arcs", "{}"),
    ("compile_s", "compile (s)", "{:.2f}"),
    ("arcs_per_s", "arcs/s", "{:,.0f}"),
    ("steps_per_arc", "steps/arc", "{:,.1f}"),
    ("executed_steps_per_arc", "executed steps/arc", "{:,.1f}"),
    ("rhs_per_arc", "RHS/arc", "{:,.0f}"),
    ("rhs_per_s", "RHS/s", "{:.3g}"),
    ("error_max_m", "worst error (m)", "{:.3g}"),
    ("error_median_m", "median error (m)", "{:.3g}"),
)


def markdown(rows, notes):
    lines = []
    for problem in ("entry", "cruise"):
        table = [
            r for r in rows if r["problem"] == problem and r["tool"] not in ("summary", "profile")
        ]
        if not table:
            continue
        lines += [
            f"\n**{problem}**\n",
            "| " + " | ".join(c[1] for c in COLUMNS) + " |",
            "|" + "---|" * 3 + "---:|" * (len(COLUMNS) - 3),
        ]
        for r in table:
            cells = [fmt.format(r[key]) if key in r else "" for key, _, fmt in COLUMNS]
            lines.append("| " + " | ".join(cells) + " |")
    summary = [r for r in rows if r["tool"] == "summary"]
    if summary:
        lines += [
            "\n**equal accuracy** (fastest setting of each within the worst error)\n",
            "| problem | worst error <= (m) | ratio | settings |",
            "|---|---:|---:|---|",
        ]
        lines += [
            f"| {r['problem']} | {r['requirement_m']:g} | {r['ratio']:.3g} "
            f"({r['method']}) | {r['setting']} |"
            for r in summary
        ]
    lines += [""] + [f"- {n}" for n in notes]
    return "\n".join(lines)


REQUIREMENTS = {"entry": (ENTRY_REQUIREMENT_M, 5.0), "cruise": (CRUISE_REQUIREMENT_M, 0.05)}


def run(quick: bool = False, arcs: int | None = None, repeats: int | None = None) -> dict:
    """The suite's entry point: both ensembles, the summary, the markdown table."""
    repeats = repeats or (2 if quick else 5)
    cores = len(jax.devices())
    rows, notes = (
        [],
        [
            f"{os.cpu_count()} cores, {cores} XLA host devices; jax {jax.__version__}"
            + "".join(f", {m} {_version(m)}" for m in ("heyoka", "numba", "scipy"))
            + "; all cores: gnc_jax vmapped and sharded over the devices, heyoka one batch "
            "integrator per thread (one thread per core), numba prange; scipy one core",
        ],
    )
    for bench, n_default, problem in (
        (entry_benchmark, 64 if quick else 1000, "entry"),
        (cruise_benchmark, 16 if quick else 200, "cruise"),
    ):
        r, bare, n = bench(quick, arcs or n_default, repeats, cores)
        rows += r
        notes += n
        s, n = summarise(rows, problem, REQUIREMENTS[problem], bare, cores, one_core=not quick)
        rows += s
        notes += n
    rows = [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]
    return {
        "title": "Open-loop propagation: gnc_jax vs heyoka, numba, scipy at equal accuracy",
        "rows": rows,
        "markdown": markdown(rows, notes),
        "notes": notes,
    }


def _version(module):
    try:
        return __import__(module).__version__
    except ImportError:
        return "not installed"


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes (under a minute)")
    p.add_argument("--arcs", type=int, default=None, help="arcs per ensemble")
    p.add_argument("--repeats", type=int, default=None)
    args = p.parse_args()
    result = run(args.quick, args.arcs, args.repeats)
    print(f"# {result['title']}")
    print(result["markdown"])


if __name__ == "__main__":
    main()
