"""The hand-written numba peer of gnc_jax's flagship closed loop, ``deep-impact-los``.

    python benchmarks/peers/numba_impactor.py [--quick] [--sizes 2000 10000] [--repeats 3]

A scalar transcription of `gnc_jax.systems.impactor.simulation.simulate` with the LOS switching-
curve law, as an expert numba user would write it (the kernel:
``benchmarks/peers/numba_impactor_kernel.py``): ``@njit(parallel=True)`` with ``prange`` over runs,
scalar code inside (vectors as three floats, the 6x6 covariance in one array per run), nothing
allocated per step, the helpers inlined, loop invariants of the coasting steps hoisted, and branches
where the work is conditional (the engine fires in about 0.5 % of the control steps). Same truth
(RK4 of the target's point-mass gravity + solar tide, thrust and mass flow held over the step), same
camera and Gaussian LOS front end, same EKF (closed-form LOS Jacobian, the two angles' scalar
updates written out, straight-line covariance growth, attitude-error rotations from power series),
same law (error ellipse at each image, switching curves of k1 and k2 sigma_B with the one-step
floor, Schmitt trigger compared multiplied out as gnc_jax compares it, zero-effort-miss thrust
direction), same error sources and the same outcome (coast to the B-plane, miss, Δv, firings, fuel,
status ``propellant``). Every number comes from ``gj.build(scenario)``; nothing is copied by hand.

Two ways to feed it random numbers:

* **fed**: the standard normals gnc_jax draws,
  `gnc_jax.systems.impactor.draws.run_draws` of each run's key, stacked over runs: the
  outcomes equal gnc_jax's run for run (``tests/test_peer_numba.py``);
* **own**: the kernel draws its own normals by the ziggurat method from a xoshiro256**
  generator per run (seeded through splitmix64 with ``seed + i`` for run ``i``), only what is
  used: 15 per run
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

import argparse
import functools
import os
import pathlib
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import gnc_jax as gj  # first: float64 and one XLA device per core

ROOT = pathlib.Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run as a script: the kernel module is imported by package
    sys.path.insert(0, str(ROOT))

from benchmarks.peers.numba_impactor_kernel import (  # noqa: E402
    AIM_FINAL,
    AIM_INITIAL,
    BURN_DRAWS,
    CTX_MASS,
    CTX_THRUST,
    CUTOFF,
    DT,
    FLOW,
    IMAGE_DRAWS,
    IMAGE_DT,
    K1,
    K2,
    MASS,
    MU,
    N_BURN_INTERVALS,
    N_FIXED,
    N_OUT,
    N_PARAMS,
    OUT_FIELDS,
    PROCESS_NOISE,
    PROPELLANT,
    R0,
    RETARGET,
    SIG_ACC_BIAS,
    SIG_ACC_NOISE,
    SIG_ATT_BIAS,
    SIG_ATT_CONTROL,
    SIG_ATT_NOISE,
    SIG_BURN,
    SIG_DELIVERY,
    SIG_FRONT_END,
    SIG_IMAGE,
    SIG_KNOW_POS,
    SIG_KNOW_VEL,
    SUN,
    THRUST,
    TIDE,
    V0,
    simulate_fed,
    simulate_own,
)

try:
    import numba
except ImportError:  # the module still imports (the suite reports the peer as missing)
    numba = None

SCENARIO = "deep-impact-los"
MODULE = "benchmarks.peers.numba_impactor"

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


def _two_pass_timer(scenario, n):
    """A timer of ``run_study`` in the impactor's two-pass layout (``LoopShape.rare``: what a
    study of ``ImpactorSystem.rare_layout.min_runs`` runs or more compiles), and its study."""
    from gnc_jax._numerics import for_platform, using_loop_shape

    system = gj.get_system(scenario.kind)
    shape = for_platform("cpu", system)._replace(rare=system.rare_layout.fraction)
    with using_loop_shape(shape):
        study = gj.run_study(scenario, runs=n, seed=0, progress=False)  # compiles

    def timer():
        c0 = time.process_time()
        with using_loop_shape(shape):
            wall = gj.run_study(scenario, runs=n, seed=0, progress=False).summary()["wall_s"]
        return wall, time.process_time() - c0

    return timer, study


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
        "f = np.zeros((2, m.N_FIXED))\n"
        "s = np.zeros((2, m.N_BURN_INTERVALS, m.BURN_DRAWS))\n"
        "im = np.zeros((2, ni, m.IMAGE_DRAWS))\n"
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
        two_pass, two_pass_study = _two_pass_timer(scenario, n)
        timers = {"study": study_wall, "batch": batch_wall, "two_pass": two_pass}
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
        rows.append(
            dict(
                name="gnc_jax run_study, two passes",
                runs=n,
                wall_s=best["two_pass"][0],
                per_s=n / best["two_pass"][0],
                cpu_us_per_run=1e6 * best["two_pass"][1] / n,
                compile_s=two_pass_study.compile_s,
                devices=two_pass_study.n_devices,
                note=(
                    "LoopShape.rare, the layout of studies from "
                    f"{gj.get_system(scenario.kind).rare_layout.min_runs:,} runs; "
                    "throughput / numba own draws' = "
                    f"{best['own'][0] / best['two_pass'][0]:.2f}"
                ),
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
                note="ziggurat normals of xoshiro256** in the kernel, only what is used",
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
        "numba own draws: ziggurat normals of a xoshiro256** generator seeded seed + i per "
        "run; 8 normals per "
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
