"""The lunar skip entry against this machine: the bare-integrator limit, a profile, the
predictor-corrector's predictions, the chunk model, and scaling with N.

    python benchmarks/capsule.py [--quick]

In one process, for ``lunar-skip-entry``:

* **limit** -- the bare vmapped RK4 ``lax.scan`` of the same truth dynamics
  (``entry_vector_field_xyz``: J2 gravity, US76 table, lift and drag, the layout of the
  closed loop), on one core for a chunk of runs, as right-hand-side evaluations per second;
* **closed loop** -- one chunk (``CapsuleSystem.chunk_per_device`` runs) on one core. Its
  evaluation rate counts the useful evaluations only: 4 per truth RK4 step flown until each
  run's chute (a finished flight waits, frozen, for the slowest run of its chunk) plus 4 per
  predictor RK4 step (``predictor_steps``); closed/bare = that rate over the bare one;
* **profile** -- the same chunk, split by measurement: the truth loop alone (the truth steps
  of the chunk's control steps), the control steps with the law but no corrector cycle, and
  the predictor step alone (all runs integrating); the corrector's cycles are the rest. Of
  those, the lock-step batch loses to waiting (a corrector cycle runs, under ``vmap``, as
  long as the run with the most predictor steps in it: most runs need 3 or 4 predictions, the
  slowest of a chunk 6 to 8) what the
  chunk spends beyond the identical chunk's corrector time per predictor step (below); the
  identical chunk's own excess over the predictor's isolated step cost is the corrector's
  overhead in the loop (per prediction: its start and end point, the root finder's
  bookkeeping, the loop's carried state);
* **ablations** -- against the default (same chunk, same core): the corrector start
  ``corrector_start = "secant"`` (planned-profile warm start, secant steps, Anderson-Bjorck:
  fewer predictions; an option, as it can settle on a lofting root at shallow entries), the
  bank held over 8 s predictor steps (the predictor before the midpoint bank at 16 s) and
  that throughout, without 32 s coast steps (the seed's predictor steps); and the
  dispersion removed (every run of the chunk the same run: the lock-step waiting
  gone, the work per run kept);
* **predictions** per trajectory of each variant (the paper gives 39.3);
* **chunk model** -- per-run time on one core against the chunk size: the working set (the
  compiled chunk's temp memory, about 2 kB per run) against the 1 MB L2 cache, and the
  lock-step waiting, which both grow with the chunk, against the per-operation overhead,
  which shrinks: ``chunk_per_device`` is the minimum;
* **scaling** -- ``gj.run_study`` on both cores for N runs, compile time apart, per-run time
  against N = 1000 (the study's equal chunks of ``chunk_per_device`` runs per core keep it
  flat); 100,000 runs are extrapolated from a measured 20,000 (per-run time flat by
  construction) unless ``--measure-100k``.

Figures in ``benchmarks/figures/``: ``capsule_scaling.png`` (wall time against N, and wall
time per run against the predictor's RK4 steps per run -- predictions times horizon -- over
the ablation variants and predictor step sizes) and ``capsule_chunks.png``.
Timings are best of ``repeats`` after a warm-up, with ``block_until_ready``, compile apart.
"""

import argparse
import dataclasses
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import gnc_jax as gj  # first: float64 and one XLA device per core
from gnc_jax.dynamics.entry import EntryArgs, entry_vector_field_xyz, to_xyz
from gnc_jax.guidance.entry.base import EntryNav, drag_and_lift
from gnc_jax.integrate import rk4_step
from gnc_jax.systems.capsule import simulation as capsule_sim

SCENARIO = "lunar-skip-entry"
FIGURES = Path(__file__).resolve().parent / "figures"


from _timing import warmed_best_of as _best  # noqa: E402  (benchmarks/_timing.py)


def _compiled(fn, *args):
    t0 = time.perf_counter()
    c = jax.jit(fn).lower(*args).compile()
    return c, time.perf_counter() - t0


def _dispersed(sim, n):
    keys = jax.vmap(lambda i: gj.run_key(0, i))(jnp.arange(n))
    return jax.vmap(lambda k: capsule_sim.dispersed_entry(sim, k))(keys)


def bare_limit(sim, n, repeats, n_steps=2500):
    """RHS evaluations/s of a vmapped RK4 scan of the truth dynamics, one core."""
    y0, vehicle, atmosphere, _ = _dispersed(sim, n)

    def one(y, vehicle, atmosphere):
        args = EntryArgs(vehicle, sim.earth, atmosphere, jnp.asarray(1.0))
        y = to_xyz(y)

        def step(c, _):
            y, t = c
            return (rk4_step(entry_vector_field_xyz, t, y, sim.dt_s, args), t + sim.dt_s), None

        (y, _), _ = jax.lax.scan(step, (y, 0.0), None, length=n_steps)
        return y.r[0]

    fn, compile_s = _compiled(jax.vmap(one), y0, vehicle, atmosphere)
    t = _best(lambda: fn(y0, vehicle, atmosphere), repeats)
    return dict(evals_per_s=4 * n_steps * n / t, ns_per_step=t / (n * n_steps) * 1e9), compile_s


def closed_loop(sim, law, n, repeats, identical=False):
    """One chunk of the closed loop on one core: wall time and the outcomes. ``identical``:
    every run of the chunk is run 7 (the same work in every lane: no run waits for another).
    The run indices are an argument, so that the identical chunk is still a batch of ``n``
    runs (a constant index would leave ``vmap`` nothing to batch: one run, broadcast)."""

    def one(i):
        return capsule_sim.simulate(sim, law, gj.run_key(0, i))[0]

    index = jnp.full((n,), 7) if identical else jnp.arange(n)
    fn, compile_s = _compiled(jax.vmap(one), index)
    t = _best(lambda: fn(index), repeats)
    out = jax.tree_util.tree_map(np.asarray, fn(index))
    return t, out, compile_s


def _per_control_step(sim, n, out, wall):
    """Control steps of a chunk's loop (to its last chute, whole corrector cycles) and the
    wall time per control step and run, ns."""
    n_control = int(np.ceil(np.max(out.t_chute_s) / sim.control_dt))
    n_control = -(-n_control // sim.pc_every) * sim.pc_every
    return n_control, wall / (n * n_control) * 1e9


def useful_evals(sim, out):
    """4 RHS per truth step flown to each run's chute and per predictor step, per run."""
    truth = np.ceil(out.t_chute_s / sim.dt_s)
    return 4.0 * (truth + out.predictor_steps)


def truth_only(sim, n, n_control, repeats):
    """ns per control step and run of the truth alone (substeps, loads, chute bookkeeping)."""
    y0, vehicle, atmosphere, _ = _dispersed(sim, n)

    def one(y0, vehicle, atmosphere):
        truth = EntryArgs(vehicle, sim.earth, atmosphere, jnp.zeros(()))
        f = capsule_sim.initial_flight(sim, y0, atmosphere)

        def control(f, _):
            sub = lambda f, _: (capsule_sim._truth_substep(sim, truth, 1.0, f), None)  # noqa: E731
            return jax.lax.scan(sub, f, None, length=sim.substeps)[0], None

        return jax.lax.scan(control, f, None, length=n_control)[0][2].load_peak

    fn, _ = _compiled(jax.vmap(one), y0, vehicle, atmosphere)
    return _best(lambda: fn(y0, vehicle, atmosphere), repeats) / (n * n_control) * 1e9


def guidance_only(sim, law, n, n_control, repeats):
    """ns per control step and run of the accelerometer measurement and the law's step
    without its corrector cycle (the state is advanced so that every step computes)."""
    y0, vehicle, atmosphere, _ = _dispersed(sim, n)
    ctx = capsule_sim.guidance_context(sim)
    no_cycle = dataclasses.replace(ctx, cycle_start=jnp.asarray(False))

    def one(y, vehicle, atmosphere):
        def measure(y):
            return EntryNav(y, *drag_and_lift(y, vehicle, sim.earth, atmosphere))

        g = law.init(measure(y), ctx)._replace(phase=jnp.asarray(1))

        def control(c, j):
            g, y = c
            command, g = law.step(g, measure(y), 40.0 + j, no_cycle)
            return (g, y._replace(r=y.r * (1.0 + 1e-9 * command))), None

        return jax.lax.scan(control, (g, y), jnp.arange(n_control))[0][0].sigma_0

    fn, _ = _compiled(jax.vmap(one), y0, vehicle, atmosphere)
    return _best(lambda: fn(y0, vehicle, atmosphere), repeats) / (n * n_control) * 1e9


def predictor_step(sim, law, n, repeats):
    """ns per RK4 step and run of the predictor, every run integrating (no waiting)."""
    _, trace = gj.simulate_one(gj.load_scenario(SCENARIO), index=0, seed=0)
    i = int(np.flatnonzero(trace.corrector_evals > 0)[10])
    from gnc_jax.dynamics.entry import EntryState
    from gnc_jax.guidance.entry.base import EntryModel
    from gnc_jax.guidance.entry.predictor import predict

    model = EntryModel(sim.vehicle, sim.earth, sim.atmosphere)
    y = EntryState(jnp.asarray(trace.r_m[i]), jnp.asarray(trace.v_mps[i]))
    sigmas = jnp.full((n,), trace.sigma_0_rad[i])

    def one(sigma):
        p = predict(law, y, trace.t_s[i], True, sigma, model, sim.target_fixed)
        return p.miss_m, p.steps

    fn, _ = _compiled(jax.vmap(one), sigmas)
    steps = int(np.max(fn(sigmas)[1]))
    return _best(lambda: fn(sigmas), repeats) / (n * steps) * 1e9


VARIANTS = {  # ablations against the default (the seed's bracketing start, midpoint bank,
    # 16 s steps, 32 s coast steps)
    "default": {},
    "secant corrector start (option)": {"corrector_start": "secant"},
    "held bank, 8 s steps": {"predictor_bank": "step", "predictor_dt_s": 8.0},
    "held bank, 8 s steps, no coast": {
        "predictor_bank": "step",
        "predictor_dt_s": 8.0,
        "predictor_coast_dt_s": 8.0,
    },
}
IDENTICAL = "default, every run identical"  # the lock-step waiting removed
STEP_VARIANTS = {  # further points for the cost-against-predictor-steps figure
    "8 s / 32 s coast": {"predictor_dt_s": 8.0},
    "12 s / 32 s coast": {"predictor_dt_s": 12.0},
    "16 s / 64 s coast": {"predictor_coast_dt_s": 64.0},
}


def chunk_curve(sim, law, chunks, total, repeats):
    """Per-run time (ms) on one core against the chunk size, and each chunk's temp memory."""
    f = jax.jit(jax.vmap(lambda i: capsule_sim.simulate(sim, law, gj.run_key(0, i))[0]))
    rows = []
    for c in chunks:
        compiled = f.lower(jnp.arange(c)).compile()
        temp = compiled.memory_analysis().temp_size_in_bytes
        n = max(total, c)
        t = _best(
            lambda c=c, n=n, f=compiled: [f(jnp.arange(s, s + c)) for s in range(0, n, c)],
            repeats,
        )
        rows.append(dict(chunk=c, ms_per_run=t / n * 1e3, temp_kb_per_run=temp / c / 1e3))
    return rows


def scaling(scenario, sizes, measure_100k):
    rows = []
    for n in sizes:
        study = gj.run_study(scenario, runs=n, seed=0, progress=False)
        s = study.summary()
        rows.append(
            dict(
                runs=n,
                chunk=study.chunk_size,
                compile_s=s["compile_s"],
                wall_s=s["wall_s"],
                ms_per_run=s["wall_s"] / n * 1e3,
                failed=s["failed"],
                extrapolated=False,
            )
        )
    if not measure_100k and sizes[-1] == 20_000:
        r = rows[-1]
        rows.append(dict(r, runs=100_000, wall_s=5 * r["wall_s"], compile_s=0.0, extrapolated=True))
    ref = next((r for r in rows if r["runs"] == 1000), rows[-1])
    for r in rows:
        r["per_run_vs_1000"] = r["ms_per_run"] / ref["ms_per_run"]
    return rows


def _figures(scale, variant_rows, chunk_rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    FIGURES.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    meas = [r for r in scale if not r["extrapolated"]]
    ax[0].loglog([r["runs"] for r in meas], [r["wall_s"] for r in meas], "o-", label="measured")
    ext = [r for r in scale if r["extrapolated"]]
    if ext:
        ax[0].loglog(
            [meas[-1]["runs"], ext[0]["runs"]],
            [meas[-1]["wall_s"], ext[0]["wall_s"]],
            "o--",
            color="C0",
            mfc="none",
            label="100,000 extrapolated from 20,000",
        )
    ax[0].set(xlabel="runs N", ylabel="study wall time after compilation (s)")
    ax[0].set_title(f"{SCENARIO}: gj.run_study on both cores")
    variant_rows = [r for r in variant_rows if r["variant"] != IDENTICAL]
    x = np.array([r["predictor_steps"] for r in variant_rows])
    y = np.array([r["ms_per_run"] for r in variant_rows])
    ax[1].plot(x, y, "o")
    for r in variant_rows:
        ax[1].annotate(r["variant"], (r["predictor_steps"], r["ms_per_run"]), fontsize=7)
    fit = np.polyfit(x, y, 1)
    xx = np.linspace(0, x.max() * 1.05, 50)
    ax[1].plot(xx, np.polyval(fit, xx), "k:", lw=1)
    ax[1].set(
        xlabel="predictor RK4 steps per run (predictions x horizon)",
        ylabel="wall time per run, one core (ms)",
        title=f"fit: {fit[1]:.2f} ms + {fit[0] * 1e6:.0f} ns per predictor step",
    )
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIGURES / "capsule_scaling.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.semilogx([r["chunk"] for r in chunk_rows], [r["ms_per_run"] for r in chunk_rows], "o-")
    ax.set(xlabel="runs per chunk (one core)", ylabel="ms per run")
    ax.set_title(f"{SCENARIO}: per-run time against the chunk")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(FIGURES / "capsule_chunks.png", dpi=110)
    plt.close(fig)


def run(quick: bool = False, measure_100k: bool = False) -> dict:
    repeats = 1 if quick else 3
    scenario = gj.load_scenario(SCENARIO)
    sim, law = gj.build(scenario)
    chunk = scenario.system.chunk_per_device
    n = 64 if quick else chunk

    bare, _ = bare_limit(sim, n, repeats)
    variant_rows, measured = [], {}
    variants = {"default": {}} if quick else {**VARIANTS, **STEP_VARIANTS, IDENTICAL: {}}
    for name, change in variants.items():
        variant = dataclasses.replace(law, **change)
        wall, out, compile_s = closed_loop(sim, variant, n, repeats, name == IDENTICAL)
        evals = useful_evals(sim, out)
        ok = out.status == 0
        variant_rows.append(
            dict(
                variant=name,
                runs=n,
                compile_s=compile_s,
                ms_per_run=wall / n * 1e3,
                predictions=float(np.mean(out.predictions)),
                predictor_steps=float(np.mean(out.predictor_steps)),
                steps_per_prediction=float(np.sum(out.predictor_steps) / np.sum(out.predictions)),
                evals_per_s=float(np.sum(evals)) / wall,
                fraction_of_bare=float(np.sum(evals)) / wall / bare["evals_per_s"],
                failed=int(np.sum(~ok)),
                downrange_std_km=float(np.std(out.downrange_err_km[ok])),
                crossrange_std_km=float(np.std(out.crossrange_err_km[ok])),
            )
        )
        measured[name] = (out, wall)

    # profile of the chunk (default): per control step of the chunk's loop
    n_control, per_control = _per_control_step(sim, n, *measured["default"])
    if quick:  # the pieces need four more compilations
        t_truth = t_guid = t_pred = float("nan")
    else:
        t_truth = truth_only(sim, n, n_control, repeats)
        t_guid = guidance_only(sim, law, n, n_control, repeats)
        t_pred = predictor_step(sim, law, n, repeats)
    corrector = per_control - t_truth - t_guid
    useful_pred = float(np.mean(measured["default"][0].predictor_steps)) * t_pred / n_control
    # the corrector without the waiting: the identical chunk's corrector time per predictor
    # step at this chunk's predictor steps; the rest of the corrector's time is waiting
    no_wait = float("nan")
    if IDENTICAL in measured:
        out_i, wall_i = measured[IDENTICAL]
        n_control_i, per_control_i = _per_control_step(sim, n, out_i, wall_i)
        steps_i = float(np.mean(out_i.predictor_steps)) / n_control_i
        no_wait = (per_control_i - t_truth - t_guid) / steps_i * useful_pred / t_pred
    truth_bare = sim.substeps * bare["ns_per_step"]  # the loop's truth steps at the limit
    profile = dict(
        closed_ns_per_control_step=per_control,
        truth_ns=t_truth,
        truth_at_bare_ns=truth_bare,
        guidance_ns=t_guid,
        corrector_ns=corrector,
        corrector_useful_ns=useful_pred,
        corrector_no_waiting_ns=no_wait,
        predictor_step_ns=t_pred,
        bare_rk4_step_ns=bare["ns_per_step"],
    )

    chunk_rows = []
    if not quick:
        chunk_rows = chunk_curve(sim, law, [32, 64, 128, 256, 512, 1024], 1024, 1)

    sizes = [100] if quick else [1, 10, 100, 1000, 10_000, 100_000 if measure_100k else 20_000]
    scale = scaling(scenario, sizes, measure_100k)
    if not quick:
        _figures(scale, variant_rows, chunk_rows)

    def share(x):
        return f"{x / per_control:.0%}"

    lines = [
        f"| bare RK4 evals/s (1 core) | closed-loop useful evals/s | closed / bare | "
        f"runs/s (1 core, chunk {n}) |",
        "|---:|---:|---:|---:|",
        f"| {bare['evals_per_s']:.3g} | {variant_rows[0]['evals_per_s']:.3g} | "
        f"{variant_rows[0]['fraction_of_bare']:.0%} | {1e3 / variant_rows[0]['ms_per_run']:.0f} |",
    ]
    pieces = [
        "",
        "| piece (ns per control step and run, 1 core) | ns | share | at its limit |",
        "|---|---:|---:|---:|",
        f"| closed loop | {per_control:.0f} | 100% | |",
        f"| truth ({sim.substeps} RK4 steps, loads, chute) | {t_truth:.0f} | {share(t_truth)} | "
        f"{truth_bare:.0f} (bare RK4) |",
        f"| measurement + law step, no corrector | {t_guid:.0f} | {share(t_guid)} | |",
        f"| corrector cycles | {corrector:.0f} | {share(corrector)} | {useful_pred:.0f} "
        f"(useful steps x {t_pred:.0f} ns) |",
        f"| - as the identical chunk's, per predictor step (no waiting) | {no_wait:.0f} | "
        f"{share(no_wait)} | |",
        f"| - lock-step waiting (the rest) | {corrector - no_wait:.0f} | "
        f"{share(corrector - no_wait)} | |",
    ]
    lines += [] if quick else pieces  # quick: the pieces are not measured
    lines += [
        "",
        "| variant | ms/run (1 core) | predictions/run | predictor steps/run | steps/prediction "
        "| useful evals / bare | failed | downrange std (km) | crossrange std (km) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in variant_rows:
        lines.append(
            f"| {r['variant']} | {r['ms_per_run']:.2f} | {r['predictions']:.1f} | "
            f"{r['predictor_steps']:.0f} | {r['steps_per_prediction']:.1f} | "
            f"{r['fraction_of_bare']:.0%} | {r['failed']} | {r['downrange_std_km']:.3f} | "
            f"{r['crossrange_std_km']:.3f} |"
        )
    if chunk_rows:
        lines += ["", "| runs per chunk (1 core) | ms/run | temp kB/run |", "|---:|---:|---:|"]
        lines += [
            f"| {r['chunk']} | {r['ms_per_run']:.2f} | {r['temp_kb_per_run']:.2f} |"
            for r in chunk_rows
        ]
    lines += [
        "",
        "| runs (2 cores) | chunk | compile (s) | wall (s) | ms/run | per run vs N=1000 |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in scale:
        ext = " (extrapolated)" if r["extrapolated"] else ""
        lines.append(
            f"| {r['runs']:,}{ext} | {r['chunk']} | {r['compile_s']:.1f} | {r['wall_s']:.2f} | "
            f"{r['ms_per_run']:.3f} | {r['per_run_vs_1000']:.2f} |"
        )

    notes = [
        f"limit, closed loop, profile and ablations on one core, {n} runs (the study's chunk "
        "per core); scaling through gj.run_study on every host device",
        "useful evaluations: 4 per truth RK4 step to each run's chute, 4 per predictor RK4 "
        "step; the predictor's steps are longer (16 s, 32 s coast) than the truth's (0.5 s), "
        "so doing less of them lowers this rate's numerator and the wall time together",
        "lock-step waiting: under vmap a corrector cycle runs as long as the run with the "
        "most predictor steps in it; the "
        f"'{IDENTICAL}' row measures the loop without that waiting (the same run in every "
        "lane, so no lane waits for another); the corrector's time beyond that, per predictor "
        "step, is the waiting",
        "paper: 39.3 predictions per trajectory (seed 003, 1000 runs)",
    ]
    if any(r["extrapolated"] for r in scale):
        notes.append("100,000 runs: 5 x the measured 20,000 (equal chunks: per-run time flat)")
    if not quick:
        notes.append(
            "figures: benchmarks/figures/capsule_scaling.png, benchmarks/figures/capsule_chunks.png"
        )
    return dict(
        title="Lunar skip entry: limit, profile, predictions, chunks and scaling",
        rows=[dict(kind="limit", **bare), dict(kind="profile", **profile)]
        + [dict(kind="variant", **r) for r in variant_rows]
        + [dict(kind="chunk", **r) for r in chunk_rows]
        + [dict(kind="scaling", **r) for r in scale],
        markdown="\n".join(lines),
        notes=notes,
    )


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes (about a minute)")
    p.add_argument("--measure-100k", action="store_true", help="measure 100,000 runs")
    args = p.parse_args()
    out = run(args.quick, args.measure_100k)
    print(out["markdown"])
    for note in out["notes"]:
        print("note:", note)


if __name__ == "__main__":
    main()
