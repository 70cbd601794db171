"""Tune the skip-entry law's four reference-tracking multipliers (seed 003 eq. 7) against the
package's hand-set defaults on lunar-skip-entry.

python examples/tune_skip_entry.py [--batch 64 --steps 30 --heldout 1000]

The objective is the RMS of the chute-deploy error (km); gradients are forward mode (the
capsule's flight is a ``while_loop`` that stops once the run is down). The held-out table
compares the defaults and the tuned gains on the same runs with the hard logic; the peak loads
of both are printed (``--load-limit G`` adds a penalty on the mean excess over G to the
objective and counts the runs beyond it).
"""

import argparse

import numpy as np

import gnc_jax as gj

p = argparse.ArgumentParser()
p.add_argument("--batch", type=int, default=64)
p.add_argument("--steps", type=int, default=30)
p.add_argument("--heldout", type=int, default=1000)
p.add_argument("--learning-rate", type=float, default=0.1)
p.add_argument("--load-limit", type=float, default=None)
p.add_argument("--check-runs", type=int, default=256, help="training runs of the hard checks")
p.add_argument("--params", default="k_drag_load,k_hdot,k_range,k_range_rate")
p.add_argument("--out", default="results/tune_skip_entry")
args = p.parse_args()

objective = "chute_rms"
if args.load_limit is not None:
    objective += f"+10*peak_load({args.load_limit:g})"
params = [f"guidance.skip_entry.{n}" for n in args.params.split(",")]
r = gj.tune(
    "lunar-skip-entry",
    params,
    objective,
    batch=args.batch,
    steps=args.steps,
    heldout_runs=args.heldout,
    learning_rate=args.learning_rate,
    check_runs=args.check_runs,
    callback=lambda rec: print(
        f"  step {rec['step']} {rec['objective']:.5g} "
        f"{np.round(rec['gains'], 4)} ({rec['wall_s']:.0f} s)",
        flush=True,
    ),  # fmt: skip
)
print(f"{dict(zip(params, r.initial, strict=True))} -> {r.tuned_gains}")
print(f"compile {r.compile_s:.1f} s, training {r.wall_s:.1f} s")
print(r.table())
for side, o in r.heldout["outcomes"].items():
    ok = o.status == 0
    load = o.load_peak_g[ok]
    beyond = "" if args.load_limit is None else f", {int((load > args.load_limit).sum())} beyond"
    print(f"{side}: peak load max {load.max():.3f} g, mean {load.mean():.3f} g{beyond}; "
          f"failed {int((~ok).sum())}")  # fmt: skip
print(r.save(args.out))
