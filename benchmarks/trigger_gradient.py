"""Is there a usable gradient of a triggered law's hard Monte Carlo objective?

    python benchmarks/trigger_gradient.py [--scenario bennu-apn] [--runs 16,64,1024]
        [--full-runs 16] [--objective "miss_rms+10*dv_mean"] [--temperatures 0.2,0.05,0.0125]
        [--reverse]

On common runs (run ``j`` = ``fold_in(key(0), j)``) of ``--scenario`` (``bennu-apn``: the APN
law's Schmitt trigger on |A|; ``deep-impact-los``: the LOS law's switching curves) with its
system's ``test_overrides`` (bennu-apn: a 2,000 s approach, 1,940 guidance steps;
``--full-runs``: also the packaged scenario, 91,200 steps for bennu-apn), for the law's
tunable gains in the tuner's coordinates theta (bennu-apn: log N0, log k,
log(trigger_on - trigger_off), log(trigger_off - 0.01); deep-impact-los: log(k1 - k2), log k2):

* a 1-D scan of the hard objective along each gain (21 points over theta +- 0.01): how many
  distinct values, how many exactly zero increments (piecewise constant) and the largest jump;
* central differences of the hard objective at steps h = 0.3, 0.1, 0.03, 0.01;
* the forward-mode gradient of the sigmoid-relaxed law at each ``--temperatures`` (``--reverse``:
  and its reverse-mode gradient) and of the
  event relaxation (``relaxation="event"``: hard switch, each switching event's crossing time
  differentiated; ``guidance.trigger.schmitt_trigger_event``), each compared with the hard
  central difference at h = 0.1 on the same runs: relative error |g - g_cd| / |g_cd|;
* why the crossings are not differentiable events: at the steps where the trigger switches,
  the one-step change of |A| (the command the trigger reads) in units of the hysteresis band
  a_on - a_off, and the share of that change that is navigation noise (|A| minus its 11-step
  moving average, RMS).
"""

import argparse
import dataclasses
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

import gnc_jax as gj
from gnc_jax import tuning
from gnc_jax.systems.intercept import simulation

GAINS = {"bennu-apn": ("n0", "k", "trigger_on", "trigger_off"), "deep-impact-los": ("k1", "k2")}
STEPS = (0.3, 0.1, 0.03, 0.01)
REFERENCE_STEP = 0.1


def setup(name: str, runs: int, full: bool, objective: str):
    scenario = gj.load_scenario(name)
    system = scenario.system
    if not full:
        scenario = gj.load_scenario(name, overrides=dict(system.test_overrides))
    law = system.law_name(scenario.config)
    names = [f"guidance.{law}.{g}" for g in GAINS[name]]
    problem = tuning.TuningProblem(
        scenario,
        tuning.resolve_gains(scenario, names),
        tuning.parse_objective(objective, scenario),
        0,
    )
    theta0 = np.asarray(problem.param.theta([scenario[n] for n in names]))
    idx, valid = problem.padded(np.arange(runs))
    return scenario, problem, theta0, idx, valid


def hard_objective(problem, idx, valid):
    """theta -> the hard objective on the runs ``idx`` (compiled once)."""
    args = problem.args
    fn = jax.jit(lambda th: problem.hard(args, problem.param.gains(th), idx, valid)[0])
    return lambda th: float(fn(jnp.asarray(th)))


def relaxed_gradient(
    problem, theta0, idx, valid, temperature, relaxation="sigmoid", gradient="forward"
):
    """Gradient (theta) of the relaxed objective in ``gradient`` mode (forward: ``jacfwd``,
    reverse: ``grad`` through the system's reverse-mode loops) and its value, and wall s."""
    sim, law, seed, w = problem.args_for(gradient)
    if hasattr(law, "relaxation"):
        law = dataclasses.replace(law, relaxation=relaxation)
    args = (sim, law, seed, w)
    fn = jax.jit(lambda th: problem.value_and_grad(args, th, temperature, idx, valid, gradient))
    t0 = time.perf_counter()
    value, grad = jax.block_until_ready(fn(jnp.asarray(theta0)))
    return float(value), np.asarray(grad), time.perf_counter() - t0


def scan(hard, theta0, i, half_width=0.01, points=21):
    """Distinct values, exactly-zero increments and the largest jump of the hard objective
    along gain ``i`` over theta0 +- ``half_width``."""
    e = np.eye(len(theta0))[i]
    values = np.array([hard(theta0 + h * e) for h in np.linspace(-half_width, half_width, points)])
    steps = np.abs(np.diff(values))
    return dict(distinct=len(np.unique(values)), zero=int((steps == 0).sum()), jumps=len(steps),
                max_jump=float(steps.max()))  # fmt: skip


def central_differences(hard, theta0, steps=STEPS):
    e = np.eye(len(theta0))
    return {h: np.array([(hard(theta0 + h * e[i]) - hard(theta0 - h * e[i])) / (2 * h)
                         for i in range(len(theta0))]) for h in steps}  # fmt: skip


def crossing_noise(scenario, runs=8):
    """At the trigger's switching steps: the one-step change of |A| over the hysteresis band
    (median), and the RMS of |A| minus its 11-step moving average over the band."""
    system = scenario.system
    sim, law = system.build(scenario)
    band = float(law.a_on_mps2 - law.a_off_mps2)
    trace = jax.jit(lambda k: simulation.simulate(sim, law, k, record=True)[1])
    jumps, noise = [], []
    for j in range(runs):
        rec = trace(jax.random.fold_in(jax.random.key(0), j))
        on, a = np.asarray(rec.engine_on), np.linalg.norm(np.asarray(rec.command_mps2), axis=1)
        firing = np.asarray(rec.t_s) < float(sim.context.cutoff_time_s)
        sw = np.nonzero(np.diff(on[firing]))[0] + 1
        jumps += list(np.abs(a[sw] - a[sw - 1]) / band)
        smooth = np.convolve(a, np.ones(11) / 11, mode="same")
        noise.append(np.sqrt(np.mean((a - smooth)[firing][5:-5] ** 2)) / band)
    return dict(switches_per_run=len(jumps) / runs, median_jump_over_band=float(np.median(jumps)),
                noise_rms_over_band=float(np.mean(noise)))  # fmt: skip


def rel_error(g, ref):
    return float(np.linalg.norm(g - ref) / np.linalg.norm(ref))


def measure(
    name, runs, full, objective, temperatures, scans=True, steps=STEPS, event=True, reverse=False
):
    scenario, problem, theta0, idx, valid = setup(name, runs, full, objective)
    hard = hard_objective(problem, idx, valid)
    t0 = time.perf_counter()
    value = hard(theta0)
    compile_s = time.perf_counter() - t0
    row = dict(scenario=name, runs=runs, full=full, hard=value, hard_first_call_s=compile_s)
    if scans:
        row["scan"] = {g: scan(hard, theta0, i) for i, g in enumerate(GAINS[name])}
    cd = central_differences(hard, theta0, steps)
    row["central"] = {str(h): v.tolist() for h, v in cd.items()}
    ref = cd[REFERENCE_STEP]
    row["central_rel_error"] = {str(h): rel_error(v, ref) for h, v in cd.items()}
    row["relaxed"] = {}
    for temp in temperatures:
        v, g, s = relaxed_gradient(problem, theta0, idx, valid, temp)
        row["relaxed"][f"sigmoid T={temp:g}"] = dict(value=v, grad=g.tolist(), s=s,
                                                     rel_error=rel_error(g, ref))  # fmt: skip
        if reverse:
            v, g, s = relaxed_gradient(problem, theta0, idx, valid, temp, gradient="reverse")
            row["relaxed"][f"sigmoid T={temp:g}, reverse"] = dict(
                value=v, grad=g.tolist(), s=s, rel_error=rel_error(g, ref)
            )
    if event and hasattr(problem.law, "relaxation"):  # the laws with an event relaxation
        v, g, s = relaxed_gradient(problem, theta0, idx, valid, problem.law_temperature, "event")
        row["relaxed"]["event"] = dict(value=v, grad=g.tolist(), s=s, rel_error=rel_error(g, ref))
    return row, scenario


def report(row):
    name = row["scenario"] + ("" if row["full"] else " (test_overrides)")
    print(f"\n{name}, {row['runs']} runs: hard objective {row['hard']:.6g}")
    for g, s in row.get("scan", {}).items():
        print(
            f"  scan {g:<11}: {s['distinct']:>2} distinct values in 21 points, theta +-0.01, "
            f"{s['zero']}/{s['jumps']} zero increments, largest jump {s['max_jump']:.3g}"
        )
    print(
        f"  {'gradient (theta)':<24}"
        + "".join(f"{g:>12}" for g in GAINS[row["scenario"]])
        + "   rel. err."
    )
    for h, v in row["central"].items():
        err = row["central_rel_error"][h]
        print(f"  {'hard CD h=' + h:<24}" + "".join(f"{x:12.4g}" for x in v) + f"   {err:8.2f}")
    for label, r in row["relaxed"].items():
        print(f"  {label:<24}" + "".join(f"{x:12.4g}" for x in r["grad"])
              + f"   {r['rel_error']:8.2f}  (value {r['value']:.6g}, {r['s']:.1f} s)")  # fmt: skip


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--scenario", default="bennu-apn", choices=sorted(GAINS))
    p.add_argument("--runs", default="16,64,1024")
    p.add_argument("--full-runs", type=int, default=0, help="also the packaged scenario")
    p.add_argument("--objective", default="miss_rms+10*dv_mean")
    p.add_argument("--temperatures", default="0.2,0.05,0.0125")
    p.add_argument("--steps", default="0.3,0.1,0.03,0.01", help="central-difference steps")
    p.add_argument("--no-event", action="store_true", help="skip the event relaxation")
    p.add_argument(
        "--reverse", action="store_true", help="also each temperature's reverse-mode gradient"
    )
    p.add_argument("--json", default="", help="write the figures to this file")
    args = p.parse_args()
    temps = [float(t) for t in args.temperatures.split(",")]
    opts = dict(
        steps=[float(h) for h in args.steps.split(",")],
        event=not args.no_event,
        reverse=args.reverse,
    )
    assert REFERENCE_STEP in opts["steps"], f"--steps must include {REFERENCE_STEP}"
    rows, scenario = [], None
    for runs in [int(r) for r in args.runs.split(",") if r]:
        row, scenario = measure(args.scenario, runs, False, args.objective, temps, **opts)
        rows.append(row)
        report(row)
    if args.full_runs:
        row, _ = measure(
            args.scenario, args.full_runs, True, args.objective, temps, scans=False, **opts
        )
        rows.append(row)
        report(row)
    if scenario is not None and args.scenario == "bennu-apn":
        noise = crossing_noise(scenario)
        print(f"\nswitching steps (8 runs, test_overrides): {noise['switches_per_run']:.0f} per "
              f"run; one-step change of |A| there: median {noise['median_jump_over_band']:.2f} "
              f"x the hysteresis band; |A| noise about its 11-step mean: "
              f"{noise['noise_rms_over_band']:.2f} x the band (RMS)")  # fmt: skip
        rows.append(noise)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
