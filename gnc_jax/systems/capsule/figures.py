"""The capsule system's report figures (seed 003 Figs. 4-6 and two of the tails): they draw
the study's runs and the traces the report layer simulated for them
(:meth:`CapsuleSystem.figure_traces <gnc_jax.systems.capsule.CapsuleSystem.figure_traces>`).
"""

import pathlib

import numpy as np

from ..._status import Status
from ...params import from_scenario
from ...plotting import ellipse_xy, pyplot, saver
from ...statistics import interval_text
from .params import CapsuleDispersions


def _chute_scatter(plt, summary, scenario, dr, cr):
    """Seed 003 Fig. 6: chute-deploy points with the 1-sigma and 3-sigma ellipses."""
    paper, n_ok = scenario.paper, len(dr)
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.scatter(cr, dr, s=5, alpha=0.5, label=f"chute deploy ({n_ok} runs)")
    ax.plot(0, 0, "r+", ms=14, mew=2, label="target")
    if n_ok > 2:
        xy = np.stack([cr, dr], axis=1)
        for k, style in ((1, "-"), (3, "--")):
            e = ellipse_xy(xy.mean(axis=0), np.cov(xy.T), k)
            ax.plot(e[0], e[1], "k" + style, lw=1, label=f"{k}σ ellipse")
    ax.add_patch(
        plt.Rectangle((-2.5, -2.5), 5, 5, fill=False, ec="C2", lw=1, label="±2.5 km (requirement)")
    )
    try:
        lo_d, hi_d = (float(x) for x in str(paper["downrange_err_km_3sigma"]).split(".."))
        lo_c, hi_c = (float(x) for x in str(paper["crossrange_err_km_3sigma"]).split(".."))
        ax.add_patch(
            plt.Rectangle(
                (lo_c, lo_d),
                hi_c - lo_c,
                hi_d - lo_d,
                fill=False,
                ec="C3",
                ls=":",
                lw=1.2,
                label="paper 3σ intervals",
            )
        )
    except (KeyError, ValueError):
        pass
    ax.set_xlabel("crossrange error (km, > 0 left)")
    ax.set_ylabel("downrange error (km, > 0 overshoot)")
    sigma3 = {
        a: summary.get(f"{a}_err_km", {}).get("three_sigma") for a in ("downrange", "crossrange")
    }
    ax.set_title(
        f"{scenario.name}: chute deploy (seed 003 Fig. 6)\n"
        f"3σ downrange {interval_text(sigma3['downrange'], 'km')}, "
        f"crossrange {interval_text(sigma3['crossrange'], 'km')}"
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    return fig


def _predictions(plt, runs, ok, scenario):
    """Seed 003 Fig. 4: predictions per trajectory and the largest count in one cycle."""
    paper = scenario.paper
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    a1.hist(runs["predictions"][ok], bins=40, color="C0")
    a1.axvline(np.mean(runs["predictions"][ok]), color="k", ls="--", label="mean (gnc_jax)")
    if "predictions_mean" in paper:
        a1.axvline(float(paper["predictions_mean"]), color="C3", ls=":", label="mean (paper)")
    a1.set_xlabel("predictions per trajectory (early-exit count)")
    a1.set_ylabel("runs")
    a1.legend(fontsize=8)
    c = runs["cycle_predictions_max"][ok].astype(int)
    a2.bar(np.arange(c.max() + 1), np.bincount(c), color="C1")
    a2.set_xlabel("most predictions in one corrector cycle")
    a2.set_ylabel("runs")
    fig.suptitle(f"{scenario.name}: predictor calls (seed 003 Fig. 4)")
    return fig


def _miss_against_ld(plt, runs, ok, scenario, dr, cr):
    """Chute miss against the dispersed lift-to-drag ratio (where the tails come from)."""
    d = from_scenario(CapsuleDispersions, scenario.config)  # 1-sigma fractions
    z = np.stack([runs[f"dispersion_{j}"] for j in range(10)], axis=1)[ok]
    ld = (1.0 + float(d.lift_frac) * z[:, 6]) / (1.0 + float(d.drag_frac) * z[:, 7])
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.semilogy(ld, np.maximum(np.hypot(dr, cr), 1e-3), ".", ms=3)
    ax.axhline(2.5, color="C2", lw=1, label="2.5 km")
    ax.set_xlabel("actual L/D over nominal L/D")
    ax.set_ylabel("chute miss (km)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(f"{scenario.name}: chute miss against the dispersed L/D")
    return fig


def _altitude_range_fan(plt, tr, scenario):
    """Seed 003 Fig. 5: altitude against range flown for every run."""
    live = tr["phase"] < 4
    fig, ax = plt.subplots(figsize=(10, 4.5))
    for i in range(len(tr["t_s"])):
        m = live[i]
        ax.plot(tr["range_flown_m"][i][m] / 1e3, tr["altitude_m"][i][m] / 1e3, lw=0.4, alpha=0.3)
    ax.axvline(scenario.config["entry"]["range_km"], color="k", ls="--", lw=1, label="target")
    ax.set_xlabel("range flown from the entry point (km)")
    ax.set_ylabel("altitude (km)")
    ax.set_title(
        f"{scenario.name}: altitude against range, {len(tr['t_s'])} runs (seed 003 Fig. 5)"
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _bank_histories(plt, tr, scenario):
    live = tr["phase"] < 4
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for i in range(min(20, len(tr["t_s"]))):
        m = live[i]
        a1.plot(tr["t_s"][i][m], np.degrees(tr["bank_rad"][i][m]), lw=0.7)
        a2.plot(tr["t_s"][i][m], tr["load_g"][i][m], lw=0.7)
    a1.set_ylabel("bank flown (deg)")
    a2.set_ylabel("sensed load (g)")
    a2.set_xlabel("time from entry interface (s)")
    a1.grid(alpha=0.3)
    a2.grid(alpha=0.3)
    fig.suptitle(f"{scenario.name}: bank angle and load, first {min(20, len(tr['t_s']))} runs")
    return fig


def capsule_figures(summary, runs, scenario, out: pathlib.Path, traces) -> list[pathlib.Path]:
    """Seed 003 Figs. 4-6 (predictions, altitude-range fan, chute scatter), bank histories and
    the chute miss against the dispersed L/D."""
    plt = pyplot()
    files = []
    save = saver(plt, out, files)
    ok = runs["status"] == Status.ok
    dr, cr = runs["downrange_err_km"][ok], runs["crossrange_err_km"][ok]
    save(_chute_scatter(plt, summary, scenario, dr, cr), "chute_scatter.png")
    if not ok.any():  # the other figures draw ok runs only: a failed study gets the scatter
        return files
    save(_predictions(plt, runs, ok, scenario), "predictions.png")
    save(_miss_against_ld(plt, runs, ok, scenario, dr, cr), "miss_vs_ld.png")
    _, tr = traces["ok_runs"]
    save(_altitude_range_fan(plt, tr, scenario), "altitude_range_fan.png")
    save(_bank_histories(plt, tr, scenario), "bank_histories.png")
    return files
