"""Tune the seed 004 augmented PN law (N0, k and the Schmitt trigger) on bennu-apn, and the
constant N = 3 law's (N0, trigger) on bennu-pn3, for the same objective; then compare the two
tuned laws on the same held-out runs: is the variable coefficient cheaper at equal miss?

python examples/tune_apn.py [--batch 16 --steps 20 --heldout 500 --weight 10]

The objective is miss RMS (m) + weight x mean Δv (m/s). Both laws fly the same held-out run
indices with the same seed, hence the same dispersion draws: the comparison is paired.
"""

import argparse
import json
import pathlib

import numpy as np

import gnc_jax as gj
from gnc_jax.tuning import paired_interval

p = argparse.ArgumentParser()
p.add_argument("--batch", type=int, default=16)
p.add_argument("--steps", type=int, default=20)
p.add_argument("--heldout", type=int, default=500)
p.add_argument("--weight", type=float, default=10.0)
p.add_argument("--check-runs", type=int, default=64, help="training runs of the hard checks")
p.add_argument("--out", default="results/tune_apn")
args = p.parse_args()
out = pathlib.Path(args.out)
objective = f"miss_rms+{args.weight:g}*dv_mean"
trigger = ["guidance.apn.trigger_on", "guidance.apn.trigger_off"]
cases = {
    "bennu-apn": ["guidance.apn.n0", "guidance.apn.k", *trigger],
    "bennu-pn3": ["guidance.apn.n0", *trigger],
}
results = {}
for name, params in cases.items():
    r = gj.tune(
        name,
        params,
        objective,
        batch=args.batch,
        steps=args.steps,
        heldout_runs=args.heldout,
        check_runs=args.check_runs,
        callback=lambda rec: print(
            f"  step {rec['step']} {rec['objective']:.5g} "
            f"{np.round(rec['gains'], 4)} ({rec['wall_s']:.0f} s)",
            flush=True,
        ),  # fmt: skip
    )
    results[name] = r
    print(f"{name}: {dict(zip(params, r.initial, strict=True))} -> {r.tuned_gains}")
    print(f"  compile {r.compile_s:.1f} s, training {r.wall_s:.1f} s")
    print(r.table(), flush=True)
    r.save(out / name)

# the two tuned laws on the same held-out runs (and the two packaged ones)
both = {n: r.heldout["outcomes"] for n, r in results.items()}
summary = {}


def dv_mean(o, i):
    return float(np.mean(o.dv_mps[i]))


def miss_rms(o, i):
    return float(np.sqrt(np.mean(o.miss_m[i] ** 2)))


for side in ("initial", "tuned"):
    a, b = both["bennu-pn3"][side], both["bennu-apn"][side]
    ok = np.flatnonzero((a.status == 0) & (b.status == 0))
    rows = {}
    for metric, stat in (("dv_mean", dv_mean), ("miss_rms", miss_rms)):
        diff, lo, hi = paired_interval(
            lambda i, a=a, stat=stat, ok=ok: stat(a, ok[i]),
            lambda i, b=b, stat=stat, ok=ok: stat(b, ok[i]),
            len(ok),
        )
        rows[metric] = dict(pn3=stat(a, ok), apn=stat(b, ok), apn_minus_pn3=diff, ci=[lo, hi])
        print(
            f"{side:8s} {metric:9s} N=3 {stat(a, ok):.4g}  variable {stat(b, ok):.4g}  "
            f"variable - N=3 {diff:+.4g} [{lo:+.4g}, {hi:+.4g}]"
        )
    summary[side] = rows
(out / "apn_vs_pn3.json").write_text(json.dumps(summary, indent=1))
print(f"wrote {out}")
