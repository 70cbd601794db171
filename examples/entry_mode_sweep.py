"""The capsule law's direct and skip entries against range, across the mode boundary.

python examples/entry_mode_sweep.py [runs] [out_dir] [ranges_km]

Runs ``lunar-skip-entry`` (``guidance.skip_entry.entry_mode = "auto"``) at its packaged entry
angle for each range (default 1600..6000 km, straddling both ends of the direct reach,
1629..3077 km at -5.9 deg within the capsule's 10 g load limit), ``runs`` runs each (default
200, seed 0), and writes ``sweep.json`` (range, mode flown, ok fraction, failures by status,
chute 3-sigma, largest peak load of the ok runs) and ``sweep.png`` (failed fraction and chute
3-sigma against range, the direct reach's ends) to ``out_dir`` (default
``results/entry-mode-sweep``). The mode flown is read from the outcome: a direct entry has no
switch point.
"""

import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import gnc_jax as gj  # noqa: E402
from gnc_jax.guidance.entry.direct import direct_reach, scan_direct  # noqa: E402
from gnc_jax.schema import ScenarioError  # noqa: E402
from gnc_jax.systems.capsule import simulation as capsule_sim  # noqa: E402
from gnc_jax.systems.capsule.reference import direct_load_limit_g, nominal_problem  # noqa: E402

RANGES_KM = (1600, 1700, 1800, 2000, 2400, 2800, 3000, 3200, 3400, 3600, 4000, 5000, 6000)


def sweep(runs, ranges_km):
    rows = []
    for r in ranges_km:
        sc = gj.load_scenario("lunar-skip-entry", [f"entry.range_km={r:g}"])
        try:
            s = gj.run_study(sc, runs=runs, seed=0, progress=False).summary()
        except ScenarioError as e:
            rows.append(dict(range_km=r, refused=str(e)))
            continue
        rows.append(
            dict(
                range_km=r,
                mode="direct" if s.get("switch_speed_mps_mean", 0.0) == 0.0 else "skip",
                runs=s["runs"],
                failed_by_status=s["failed_by_status"],
                ok_fraction=1 - s["failed"] / s["runs"],
                chute_3sigma_km=s.get("chute_3sigma_km"),
                load_peak_g_max=s.get("load_peak_g_max"),
            )
        )
        print(json.dumps(rows[-1]), flush=True)
    return rows


def figure(rows, reach_km, path):
    rows = [r for r in rows if "mode" in r]
    fig, (a, b) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    x = [r["range_km"] for r in rows]
    a.plot(x, [100 * (1 - r["ok_fraction"]) for r in rows], "k-", lw=0.8, zorder=0)
    b.plot(x, [r["chute_3sigma_km"] for r in rows], "k-", lw=0.8, zorder=0)
    for mode, marker in (("direct", "o"), ("skip", "s")):
        rr = [r for r in rows if r["mode"] == mode]
        xs = [r["range_km"] for r in rr]
        a.plot(xs, [100 * (1 - r["ok_fraction"]) for r in rr], marker, ms=7, label=f"{mode} entry")
        b.plot(xs, [r["chute_3sigma_km"] for r in rr], marker, ms=7, label=f"{mode} entry")
    for ax in (a, b):
        ax.axvline(reach_km[0], color="r", ls=":", lw=1.2, label="direct reach starts (load)")
        ax.axvline(reach_km[1], color="r", ls="--", lw=1.2, label="direct reach ends")
        ax.grid(alpha=0.3)
    a.axhline(0.5, color="g", ls=":", lw=1, label="0.5 %")
    b.axhline(5.0, color="g", ls=":", lw=1, label="5 km")
    a.set_ylabel("failed runs, %")
    b.set_ylabel("chute 3σ of ok runs, km")
    b.set_xlabel("entry.range_km")
    a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    out = pathlib.Path(sys.argv[2] if len(sys.argv) > 2 else "results/entry-mode-sweep")
    ranges = [float(x) for x in sys.argv[3].split(",")] if len(sys.argv) > 3 else RANGES_KM
    out.mkdir(parents=True, exist_ok=True)
    sc = gj.load_scenario("lunar-skip-entry")
    problem = nominal_problem(sc.config, capsule_sim.build(sc), 0.2)
    law = gj.get_system("capsule").laws()["skip_entry"]
    reach = direct_reach(scan_direct(problem, direct_load_limit_g(law, sc.config)))
    reach_km = [sc.config["entry"]["range_km"] + x / 1e3 for x in reach]
    rows = sweep(runs, ranges)
    (out / "sweep.json").write_text(json.dumps(rows, indent=1))
    figure(rows, reach_km, out / "sweep.png")


if __name__ == "__main__":
    main()
