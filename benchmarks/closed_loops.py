"""The closed loops against this machine's limit: throughput, scaling with N, and a profile.

    python benchmarks/closed_loops.py [--quick]

For each closed loop (the ``deep-impact-los`` impactor and the ``bennu-apn`` intercept), in one
process:

* **limit** -- the bare vmapped ``lax.scan`` of the same truth step (the impactor's RK4, the
  intercept's drift-kick-drift step; the engine firing, every run its own state), 1000 runs
  on one core, as right-hand-side evaluations/s;
* **profile** -- the closed loop on one core at the same batch, in ns per control step and
  run, split by measurement: the bare integrator; the control steps alone (the same
  simulation with every image interval merged into one, so no image, filter update or draw
  but the first); and the whole loop. Integrator share = bare / closed; guidance step and
  bookkeeping = (steps-only - bare) / closed; images (draws, camera, filter update,
  covariance) = (closed - steps-only) / closed. The closed loop's fraction of the bare rate
  is bare / closed (both evaluate the truth as often per step);
* **scaling** -- ``gj.run_study`` on both cores for N runs, compile time apart, wall time and
  per-run time against the 1000-run figure (the study's own chunking: at most 1024 runs
  per compiled call, so per-run time should stay flat), and a figure
  ``benchmarks/figures/scaling.png``.

Timings are best of ``repeats`` after a warm-up, with ``block_until_ready``.
"""

import argparse
import dataclasses

import jax
import jax.numpy as jnp

import gnc_jax as gj  # first: float64 and one XLA device per core

PROFILE_BATCH = 1000


from _timing import warmed_best_of as _best  # noqa: E402  (benchmarks/_timing.py)


def _impactor_bare(sim):
    from gnc_jax._numerics import as_array, as_v3
    from gnc_jax.dynamics.impactor import ImpactorState, rk4

    n = sim.n_images * sim.steps_per_image

    # The engine firing all along (thrust along the B-plane T axis, its mass flow): the truth
    # dynamics as the closed loop integrates it. Without thrust a gravity-free truth (the
    # paper scenarios, RelativeDynamics.of) is a constant velocity, which XLA folds away.
    thrust = sim.engine.thrust_n * sim.context.c_bi[1]
    flow = sim.engine.mass_flow(1.0)

    def bare(r0):
        # The state carried by components (V3), the integrator's fastest form on XLA CPU
        # (3x the (batch, 3) carry): the limit is the best formulation, not ours.
        # every run its own velocity and mass (as in the closed loop), or XLA computes the
        # shared parts once for the batch
        d = r0 - sim.r0_m
        v0 = sim.v0_mps + 1e-6 * d
        y = ImpactorState(as_v3(r0), as_v3(v0), sim.mass_kg + 1e-6 * d[0])
        step = lambda y, _: (rk4(sim.dynamics, y, thrust, flow, sim.context.dt_s), None)
        return as_array(jax.lax.scan(step, y, None, length=n)[0].r)

    return bare, n


def _intercept_bare(sim):
    from gnc_jax.dynamics.intercept import drift_kick_drift_step

    n = sim.n_images * sim.steps_per_image
    dt = sim.context.dt_s
    # The closed loop's truth step (one gravity evaluation per step), the engine on at the
    # guidance's pulse fraction (as the closed loop fires it), per-run position.
    throttle = sim.context.pulse_fraction
    thrust = throttle * sim.engine.thrust_n * sim.c_bi[1]
    flow = throttle * sim.engine.mass_flow(1.0)

    def bare(r0):
        y = sim.y0._replace(r=r0)
        step = lambda y, _: (drift_kick_drift_step(sim.dynamics, y, thrust, flow, dt), None)
        return jax.lax.scan(step, y, None, length=n)[0].r

    return bare, n


EVALUATIONS_PER_STEP = {"impactor": 4, "intercept": 1}
"""Truth right-hand sides per control step: RK4 for the impactor, the intercept's
drift-kick-drift step (``dynamics.intercept.drift_kick_drift_step``)."""


def profile(name, repeats, max_steps=None):
    """ns per control step and run of the bare integrator, the steps alone and the loop."""
    scenario = gj.load_scenario(name)
    system = scenario.system
    sim, law = gj.build(scenario)
    if max_steps and sim.n_images * sim.steps_per_image > max_steps:  # long loops: a prefix
        sim = dataclasses.replace(sim, n_images=max_steps // sim.steps_per_image)
    impactor = scenario.kind == "impactor"
    bare, n = (_impactor_bare if impactor else _intercept_bare)(sim)
    steps_only = dataclasses.replace(sim, n_images=1, steps_per_image=n)
    b = PROFILE_BATCH
    keys = jax.vmap(lambda i: gj.run_key(0, i))(jnp.arange(b))
    loop = jax.jit(
        jax.vmap(lambda s, l, k: system.simulate(s, l, k)[0].miss_m, in_axes=(None, None, 0))
    )
    r0 = jax.vmap(lambda i: sim_r0(sim) + i)(jnp.arange(b, dtype=float))
    bare_fn = jax.jit(jax.vmap(bare))
    times = {
        "bare": _best(lambda: bare_fn(r0), repeats),
        "steps_only": _best(lambda: loop(steps_only, law, keys), repeats),
        "closed": _best(lambda: loop(sim, law, keys), repeats),
    }
    ns = {k: v / (b * n) * 1e9 for k, v in times.items()}
    return dict(
        loop=name,
        steps=n,
        bare_ns=ns["bare"],
        steps_only_ns=ns["steps_only"],
        closed_ns=ns["closed"],
        bare_evals_per_s=EVALUATIONS_PER_STEP[scenario.kind] / ns["bare"] * 1e9,
        fraction_of_bare=ns["bare"] / ns["closed"],
        share_integrator=ns["bare"] / ns["closed"],
        share_guidance_step=(ns["steps_only"] - ns["bare"]) / ns["closed"],
        share_images=(ns["closed"] - ns["steps_only"]) / ns["closed"],
    )


def sim_r0(sim):
    return sim.r0_m if hasattr(sim, "r0_m") else sim.y0.r


def scaling(name, sizes):
    """``gj.run_study`` on every core: compile and wall time per N."""
    scenario = gj.load_scenario(name)
    rows = []
    for n in sizes:
        s = gj.run_study(scenario, runs=n, seed=0, progress=False).summary()
        rows.append(
            dict(
                loop=name,
                runs=n,
                compile_s=s["compile_s"],
                wall_s=s["wall_s"],
                runs_per_s=n / s["wall_s"],
                us_per_run=s["wall_s"] / n * 1e6,
                failed=s["failed"],
            )
        )
    ref = next((r for r in rows if r["runs"] == 1000), rows[-1])
    for r in rows:
        r["per_run_vs_1000"] = r["us_per_run"] / ref["us_per_run"]
    return rows


def _figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for loop in sorted({r["loop"] for r in rows}):
        rr = [r for r in rows if r["loop"] == loop]
        ax[0].loglog([r["runs"] for r in rr], [r["wall_s"] for r in rr], "o-", label=loop)
        ax[1].semilogx([r["runs"] for r in rr], [r["us_per_run"] for r in rr], "o-", label=loop)
    ax[0].set(xlabel="runs N", ylabel="wall time after compilation (s)", title="study wall time")
    ax[1].set(xlabel="runs N", ylabel="us per run", title="per-run time (2 cores)")
    ax[1].set_yscale("log")
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
        a.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(quick: bool = False) -> dict:
    from pathlib import Path

    repeats = 2 if quick else 3
    prof = [
        profile("deep-impact-los", repeats),
        profile("bennu-apn", repeats, max_steps=5000),  # a 5000-step prefix of 91,800
    ]
    if quick:
        sizes = {"deep-impact-los": [1, 100, 1000], "bennu-apn": [1, 10, 100]}
    else:
        sizes = {
            "deep-impact-los": [1, 10, 100, 1000, 10_000, 100_000],
            "bennu-apn": [1, 10, 100, 1000, 2000],
        }
    scale = [row for name, ns in sizes.items() for row in scaling(name, ns)]
    _figure(scale, Path(__file__).parent / "figures" / "scaling.png")

    lines = [
        "| loop | bare evals/s (1 core) | bare ns/step | steps-only ns/step | closed ns/step "
        "| closed / bare rate | integrator | guidance step | images |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for p in prof:
        lines.append(
            f"| {p['loop']} | {p['bare_evals_per_s']:.3g} | {p['bare_ns']:.1f} | "
            f"{p['steps_only_ns']:.1f} | {p['closed_ns']:.1f} | {p['fraction_of_bare']:.0%} | "
            f"{p['share_integrator']:.0%} | {p['share_guidance_step']:.0%} | "
            f"{p['share_images']:.0%} |"
        )
    lines += [
        "",
        "| loop | runs | compile (s) | wall (s) | runs/s | us/run | per run vs N=1000 |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in scale:
        lines.append(
            f"| {r['loop']} | {r['runs']:,} | {r['compile_s']:.1f} | {r['wall_s']:.3f} | "
            f"{r['runs_per_s']:,.0f} | {r['us_per_run']:,.0f} | {r['per_run_vs_1000']:.2f} |"
        )
    return dict(
        title="Closed loops against the machine: bare-integrator limit, profile, scaling",
        rows=prof + scale,
        markdown="\n".join(lines),
        notes=[
            f"profile on one core, {PROFILE_BATCH} runs per batch; bennu-apn profiled on a "
            "5000-step prefix of its 91,800 steps; scaling on every host device via "
            "gj.run_study (compile time apart); figure benchmarks/figures/scaling.png",
        ],
    )


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    args = p.parse_args()
    out = run(args.quick)
    print(out["markdown"])
    for n in out["notes"]:
        print("note:", n)


if __name__ == "__main__":
    main()
