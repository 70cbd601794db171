"""PNG reports of a study directory written by ``gnc-jax run`` (``gnc-jax report DIR``)."""

import pathlib

import numpy as np

from ._status import Status


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _ellipse_xy(mean, cov, k, n=200):
    """Points of the k-sigma ellipse of a 2-D covariance (seed 000 eq. 17)."""
    vals, vecs = np.linalg.eigh(cov)
    a = np.linspace(0.0, 2.0 * np.pi, n)
    circle = np.stack([np.cos(a), np.sin(a)])
    return mean[:, None] + k * vecs @ (np.sqrt(np.maximum(vals, 0.0))[:, None] * circle)


def _impactor_figures(summary, runs, scenario, out: pathlib.Path) -> list[pathlib.Path]:
    from .geometry.ellipse import ellipse_probability
    from .montecarlo import simulate_one

    plt = _plt()
    ok = runs["status"] == Status.ok
    files = []
    aim = np.array(scenario.config["guidance"]["aim_final_km"]) * 1e3
    b = np.stack([runs["b_t_m"][ok], runs["b_r_m"][ok]], axis=1)

    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.scatter(b[:, 0] - aim[0], b[:, 1] - aim[1], s=4, alpha=0.5, label=f"impacts ({ok.sum()})")
    ax.plot(0, 0, "r+", ms=14, mew=2, label=f"aim point ({aim[0]:g}, {aim[1]:g}) m")
    if len(b) > 2:
        mean = b.mean(axis=0) - aim
        cov = np.cov(b.T)
        for k, style in ((1, "-"), (3, "--")):
            xy = _ellipse_xy(mean, cov, k)
            p = float(ellipse_probability(k))
            ax.plot(xy[0], xy[1], "k" + style, lw=1, label=f"{k}σ ellipse (P = {p:.3f})")
    ax.set_xlabel("B·T − aim (m)")
    ax.set_ylabel("B·R − aim (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(
        f"{scenario.name}: B-plane impact points\n"
        f"miss RMS {summary.get('miss_rms_m', np.nan):.1f} m, "
        f"max {summary.get('miss_max_m', np.nan):.1f} m"
    )
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    files.append(out / "b_plane.png")
    fig.savefig(files[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    a1.hist(runs["dv_mps"][ok], bins=40, color="C0")
    a1.axvline(summary.get("dv_mean_mps", np.nan), color="k", ls="--", label="mean")
    a1.set_xlabel("total Δv (m/s)")
    a1.set_ylabel("runs")
    a1.legend()
    f = runs["firings"][ok].astype(int)
    counts = np.bincount(f) if f.size else np.zeros(1)
    a2.bar(np.arange(len(counts)), counts, color="C1")
    a2.set_xlabel("engine firings")
    a2.set_ylabel("runs")
    fig.suptitle(f"{scenario.name}: Δv and firings ({ok.sum()} runs)")
    files.append(out / "dv_firings.png")
    fig.savefig(files[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)

    # Fig. 3 of seed 000 for the first run: |omega| against the switching curves.
    _, trace = simulate_one(scenario, index=0, seed=summary.get("seed"))
    t = trace.t_s
    tgo = t[-1] - t
    fig, ax = plt.subplots(figsize=(9, 4.5))
    if scenario.config["guidance"]["law"] == "los":
        ls = trace.law_state
        ax.semilogy(t, ls.omega, lw=1, label="|ω| (navigation)")
        ax.semilogy(t, ls.omega_open, lw=1, label="ω_open (k1)")
        ax.semilogy(t, ls.omega_close, lw=1, label="ω_close (k2)")
        ax.set_ylabel("LOS rate (rad/s)")
        lo = np.nanmin(np.where(ls.omega > 0, ls.omega, np.nan))
        ax.set_ylim(max(lo, 1e-12), None)
        title = "LOS rate and switching curves (seed 000 Fig. 3), run 0"
    else:
        ax.set_ylabel("throttle")
        title = "burns of the predictive law, run 0"
    ax2 = ax.twinx()
    ax2.fill_between(t, 0, trace.throttle, step="post", color="C3", alpha=0.3, label="engine")
    ax2.set_ylim(0, 4)
    ax2.set_yticks([0, 1])
    ax2.set_ylabel("engine on")
    ax.set_xlabel("mission time (s)")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="upper left", fontsize=8)
    ax.set_title(f"{scenario.name}: {title}")
    ax.grid(alpha=0.3)
    del tgo
    files.append(out / "engine_trace.png")
    fig.savefig(files[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)
    return files


FIGURES = {"impactor": _impactor_figures}


def report(run_dir, out_dir=None) -> list[str]:
    """Write the PNG figures of a study directory; returns their paths.

    Args:
        run_dir: a directory written by ``gnc-jax run`` / :meth:`Study.save`.
        out_dir: where to write the PNGs (default: ``run_dir``).
    """
    from .results import load_results

    summary, runs, scenario = load_results(run_dir)
    if scenario.kind not in FIGURES:
        raise FileNotFoundError(
            f"report: no figures for {scenario.kind!r} studies yet; "
            f"allowed: {', '.join(FIGURES)} studies"
        )
    out = pathlib.Path(out_dir or run_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [str(p) for p in FIGURES[scenario.kind](summary, runs, scenario, out)]
