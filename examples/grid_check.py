"""Local check of a gain setting on held-out runs, hard logic: each gain scaled by 1 -+ STEP
alone (a coordinate grid), plus the relaxed objective's gradient on training runs.

python examples/grid_check.py SCENARIO OBJECTIVE gain1,gain2,... [--step 0.25 --runs 500]
"""

import argparse

import jax
import jax.numpy as jnp
import numpy as np

import gnc_jax as gj
from gnc_jax import tuning

p = argparse.ArgumentParser()
p.add_argument("scenario")
p.add_argument("objective")
p.add_argument("params")
p.add_argument("--at", default=None, help="comma-separated gains (default: the scenario's)")
p.add_argument("--step", type=float, default=0.25)
p.add_argument("--runs", type=int, default=500)
p.add_argument("--gradient-runs", type=int, default=64)
args = p.parse_args()

scenario = gj.load_scenario(args.scenario)
params = args.params.split(",")
centre = [float(x) for x in args.at.split(",")] if args.at else [scenario[n] for n in params]
points = [list(centre)]
for i in range(len(params)):
    for f in (1 - args.step, 1 + args.step):
        g = list(centre)
        g[i] *= f
        points.append(g)
order = tuning.resolve_gains(scenario, params)
param = tuning.Reparametrisation.of(scenario, order)
valid = [g for g in points if np.all(np.isfinite(param.theta(g)))] if points else []
scores = tuning.hard_scores(scenario, params, args.objective, valid, args.runs)
for g, (v, failed) in zip(valid, scores, strict=True):
    note = f", {failed} failed runs" if failed else ""
    print(f"{np.round(g, 4)}: {v:.5g} ({100 * (v / scores[0][0] - 1):+.2f} %{note})", flush=True)
best = min(range(len(scores)), key=lambda i: tuning.ranking_key(*scores[i]))
print(f"best (fewest failed runs, then the objective): {np.round(valid[best], 4)}", flush=True)

problem = tuning.TuningProblem(scenario, order, tuning.parse_objective(args.objective, scenario), 0)
idx, w = problem.padded(np.arange(args.gradient_runs))
theta = jnp.asarray(param.theta(centre))
grad = jax.jit(jax.jacfwd(lambda th: problem.smooth(problem.args, th, problem.law_temperature,
                                                    idx, w)))(theta)  # fmt: skip
print(f"relaxed gradient in log-gain units on {args.gradient_runs} training runs: "
      f"{np.round(np.asarray(grad), 3)}, norm {float(jnp.linalg.norm(grad)):.4g}")  # fmt: skip
