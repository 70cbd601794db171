"""A gain schedule (16 knots for the LOS law by default) tuned three ways on the same runs per
step: Adam on reverse-mode gradients through the relaxed switch, the package's antithetic ES
and CMA-ES (the ``cma`` package) on the hard logic.

    python benchmarks/tune_schedule.py [--batch 64] [--steps 30] [--heldout 2000]
        [--eval-every 2] [--eval-runs 256] [--methods adam,es,cma] [--population 4]
        [--check-runs 256] [--setup los|skip-entry|skip-entry-gains] [--breakpoints 0,...]
        [--learning-rate 0.1] [--sigma 0.1]

``deep-impact-los`` with k1 and k2 scheduled over time to go at 8 breakpoints each (16
knots), starting from the packaged constant gains (4, 1) at every knot (the same flight as
the packaged law); ``--setup skip-entry``: ``lunar-skip-entry``'s overall tracking gain
k_range scheduled over speed at 6 breakpoints, chute-deploy RMS error; ``--setup
skip-entry-gains``: all four tracking gains so scheduled (24 knots). Each method:
``gj.tune`` with the same batch, steps and seed (the training check on ``--check-runs``
runs); the hard objective on ``--eval-runs`` held-out runs every ``--eval-every`` steps
(not timed); the final paired comparison against the packaged gains on ``--heldout``
held-out runs with its 95 % bootstrap interval. The baselines are CMA-ES and the ES: each
one's final monitored held-out objective is a target, and each method's runs and training
wall time (compile apart, monitoring not counted) to reach it are printed, as a ratio to
the baseline's.
"""

import argparse
import time

import gnc_jax as gj

SETUPS = {
    # scenario, breakpoints field and values, schedules tuned, objective
    "los": (
        "deep-impact-los",
        "guidance.los.schedule_tgo_s",
        [0.0, 120.0, 300.0, 600.0, 1200.0, 2400.0, 4800.0, 7200.0],
        "guidance.los.k1_schedule,guidance.los.k2_schedule",
        "miss_rms+10*dv_mean",
    ),
    "skip-entry": (
        "lunar-skip-entry",
        "guidance.skip_entry.schedule_speed_kmps",
        [0.5, 2.0, 4.0, 6.0, 8.0, 11.0],
        "guidance.skip_entry.k_range_schedule",
        "chute_rms",
    ),
    "skip-entry-gains": (
        "lunar-skip-entry",
        "guidance.skip_entry.schedule_speed_kmps",
        [0.5, 2.0, 4.0, 6.0, 8.0, 11.0],
        "guidance.skip_entry.k_range_schedule,guidance.skip_entry.k_drag_load_schedule,"
        "guidance.skip_entry.k_hdot_schedule,guidance.skip_entry.k_range_rate_schedule",
        "chute_rms",
    ),
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--heldout", type=int, default=2000)
    ap.add_argument("--eval-every", type=int, default=2)
    ap.add_argument("--eval-runs", type=int, default=256)
    ap.add_argument("--methods", default="adam,es,cma")
    ap.add_argument("--population", type=int, default=4)
    ap.add_argument("--check-runs", type=int, default=256)
    ap.add_argument("--setup", choices=tuple(SETUPS), default="los")
    ap.add_argument("--breakpoints", help="the schedule's breakpoints, comma-separated")
    ap.add_argument("--learning-rate", type=float, default=0.1, help="Adam's and the ES's")
    ap.add_argument("--sigma", type=float, default=0.1, help="the ES's and CMA-ES's step")
    args = ap.parse_args()
    name, field, breakpoints, params, objective = SETUPS[args.setup]
    if args.breakpoints:
        breakpoints = [float(b) for b in args.breakpoints.split(",")]
    scenario = gj.load_scenario(name, overrides={field: breakpoints})
    results = {}
    for method in args.methods.split(","):
        t0 = time.perf_counter()
        r = gj.tune(
            scenario, params, objective, batch=args.batch, steps=args.steps, seed=0,
            method=method, heldout_runs=args.heldout, eval_every=args.eval_every,
            eval_runs=args.eval_runs, population=args.population, check_runs=args.check_runs,
            learning_rate=args.learning_rate, sigma=args.sigma,
        )  # fmt: skip
        results[method] = r
        row = r.heldout["rows"][0]
        print(
            f"{method}: compile {r.compile_s:.1f} s, training {r.wall_s:.1f} s (total "
            f"{time.perf_counter() - t0:.0f} s); held-out {r.heldout['paired_runs']} runs: "
            f"objective {row['initial']:.2f} -> {row['tuned']:.2f} ({100 * row['relative']:+.1f}"
            f" %, 95 % CI of the difference [{row['ci_low']:.2f}, {row['ci_high']:.2f}])",
            flush=True,
        )
        print(r.table(), flush=True)
        print("  knots", [round(v, 3) for v in r.tuned], flush=True)
    for baseline in ("cma", "es"):
        if baseline in results:
            print_reach(results, baseline)


def print_reach(results, baseline):
    """Each method's runs and training wall time to the baseline's final monitored held-out
    objective, as a ratio to the baseline's own."""
    monitored = [h for h in results[baseline].history if h.get("heldout") is not None]
    target = monitored[-1]  # its objective and failed runs: fewer failed runs rank first
    print(
        f"target: {baseline}'s final monitored held-out objective {target['heldout']:.3f}"
        f" ({target.get('heldout_failed', 0)} failed)"
    )
    own = results[baseline].runs_to_reach(target)
    for method, r in results.items():
        reach = r.runs_to_reach(target)
        best = r.best_heldout()  # fewest failed runs, then the objective
        if reach is None:
            print(
                f"  {method}: not reached (best monitored {best['heldout']:.3f}, "
                f"{best.get('heldout_failed', 0)} failed)"
            )
            continue
        ratio = reach[1] / own[1] if own[1] > 0 else float("nan")
        print(f"  {method}: {reach[0]} runs, {reach[1]:.2f} s ({ratio:.2f}x {baseline}'s)")


if __name__ == "__main__":
    main()
