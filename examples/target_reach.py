"""Whether a capsule study's worst runs could have reached the target at all.

python examples/target_reach.py RUNS WORST [--set field=value ...]

Runs ``lunar-skip-entry`` (with the ``--set`` overrides, e.g. ``entry.fpa_deg=-6.4
entry.range_km=10000 vehicle.cl=0.286 vehicle.mass_kg=17160``) for ``RUNS`` runs, seed 0, and
for its ``WORST`` runs of largest chute miss (and two of the smallest, for contrast) flies
each run's own dispersed vehicle, atmosphere and entry state open loop in three dimensions at
every constant bank magnitude reversed once
(:func:`gnc_jax.systems.capsule.envelope.target_reach`). Prints, per run, its status, its
miss and the crossrange span its flights land at on the target's downrange: a span that does
not hold 0 is a run that no such bank brings to the target, and its nearer end is about how
close one comes.
"""

import sys

import numpy as np

import gnc_jax as gj
from gnc_jax.systems.capsule.envelope import target_reach


def main():
    runs, worst = int(sys.argv[1]), int(sys.argv[2])
    overrides = [a for a in sys.argv[3:] if a != "--set"]
    sc = gj.load_scenario("lunar-skip-entry", overrides)
    study = gj.run_study(sc, runs=runs, seed=0, progress=False)
    o = study.outcomes
    miss = np.maximum(np.abs(o["downrange_err_km"]), np.abs(o["crossrange_err_km"]))
    order = np.argsort(-miss)
    chosen = np.concatenate([order[:worst], order[-2:]])
    spans = target_reach(sc.config, chosen, seed=0)
    print("run  status          miss_km  downrange_km  crossrange_km  span_km            reaches")
    for i, (lo, hi) in zip(chosen, spans):
        print(
            f"{i:4d}  {gj.Status.name_of(o['status'][i]):14s}  {miss[i]:7.1f}  "
            f"{o['downrange_err_km'][i]:12.1f}  {o['crossrange_err_km'][i]:13.1f}  "
            f"[{lo:7.1f}, {hi:7.1f}]  {bool(lo <= 0.0 <= hi)}"
        )


if __name__ == "__main__":
    main()
