"""PNG reports of a study directory written by ``gnc-jax run`` (``gnc-jax report DIR``)."""

import pathlib

import numpy as np

from ._status import Status


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _saver(plt, out: pathlib.Path, files: list):
    """``save(fig, name)``: write ``out/name`` at 120 dpi, close the figure, record the path."""

    def save(fig, name):
        files.append(out / name)
        fig.savefig(files[-1], dpi=120, bbox_inches="tight")
        plt.close(fig)

    return save


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
    files.append(out / "engine_trace.png")
    fig.savefig(files[-1], dpi=120, bbox_inches="tight")
    plt.close(fig)
    files.append(_centroid_frames_figure(scenario, trace, out))
    return files


def _centroid_frames_figure(scenario, trace, out: pathlib.Path) -> pathlib.Path:
    """Seed 002 Fig. 7: rendered frames of run 0 with the extracted centroid marked.

    Frames at four mission times along run 0's true trajectory, rendered by the image front
    end with the scenario's camera and target (camera pointed at the navigation estimate, no
    attitude error), centroided by the seed 002 pipeline. Shown for every impactor study: with
    ``navigation.measurement = "noise"`` it illustrates what the noise model stands for.
    """
    import jax
    import jax.numpy as jnp

    from .navigation.camera import camera_attitude, los_angles
    from .navigation.centroid import extract_centroid
    from .navigation.render import (
        choose_binning,
        phase_offset_tangent,
        render_frame,
        tangent_to_roi,
    )
    from .simulation.impactor import build

    plt = _plt()
    sim, _ = build(scenario)
    cam, tgt = sim.camera, sim.target
    t_end = float(trace.t_s[-1])
    times = [0.0, 0.5 * t_end, 0.85 * t_end, t_end - 660.0]  # the last: ~12 min before impact
    err = sim.errors
    pointing = float(np.hypot(err.image_processing_rad, err.attitude_noise_rad))
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.4))
    for n, (ax, t) in enumerate(zip(axes, times)):
        i = int(np.clip(np.searchsorted(trace.t_s, t), 0, len(trace.t_s) - 1))
        r, r_hat = jnp.asarray(trace.r_m[i]), jnp.asarray(trace.r_hat_m[i])
        c = camera_attitude(-r_hat, sim.context.c_bi[2])
        uv_pred = los_angles(c, -r_hat)
        rho = jnp.linalg.norm(r_hat)
        disc = jnp.arcsin(jnp.minimum(tgt.bounding_radius_m / rho, 0.999))
        b = choose_binning(cam, disc, pointing)
        frame = render_frame(cam, tgt, c, -r, uv_pred, b, jax.random.key(n))
        cen = extract_centroid(frame.dn, cam.window_px, cam.label_iterations)
        true_xy = tangent_to_roi(cam, frame.origin_px, frame.bin, los_angles(c, -r))
        corr = phase_offset_tangent(c, r_hat, tgt.sun_direction, tgt.mean_radius_m)
        corr_xy = cen.xy - corr / (cam.ifov_rad * frame.bin)
        ax.imshow(np.asarray(frame.dn), cmap="gray", origin="lower")
        ax.plot(*np.asarray(cen.xy), "r+", ms=16, mew=2, label="centroid (seed 002 §3.1)")
        if scenario.config["navigation"]["phase_correction"]:
            ax.plot(*np.asarray(corr_xy), "yx", ms=9, mew=1.5, label="phase-corrected")
        ax.plot(*np.asarray(true_xy), "co", ms=6, mfc="none", label="true centre")
        ax.set_title(
            f"t = {float(trace.t_s[i]):.0f} s, range {float(rho) / 1e3:,.0f} km\n"
            f"bin {int(frame.bin)} ({float(cam.ifov_rad * frame.bin) * 1e6:.0f} µrad/px), "
            f"threshold {float(cen.threshold_dn):.0f} DN",
            fontsize=9,
        )
        ax.set_xticks([])
        ax.set_yticks([])
    axes[0].legend(loc="upper left", fontsize=7)
    fig.suptitle(f"{scenario.name}: rendered ROI frames and extracted centroids (seed 002 Fig. 7)")
    path = out / "centroid_frames.png"
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


def _midcourse_figures(summary, runs, scenario, out: pathlib.Path) -> list[pathlib.Path]:
    """B-plane dispersion, seed 001 Figs. 1-4 and where the sensitivity methods depart."""
    import jax.numpy as jnp

    from .simulation import midcourse

    plt = _plt()
    ok = runs["status"] == Status.ok
    files = []

    save = _saver(plt, out, files)

    goal_km = scenario.config["goal"]["b_km"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, prefix, title in ((axes[0], "b0", "before correction"), (axes[1], "b", "after")):
        bt, br = runs[f"{prefix}_err_t_m"][ok] / 1e3, runs[f"{prefix}_err_r_m"][ok] / 1e3
        ax.scatter(bt, br, s=6, alpha=0.6, label=f"runs ({ok.sum()})")
        goal = plt.Circle((0, 0), goal_km, fill=False, color="r", label=f"goal {goal_km:g} km")
        ax.add_patch(goal)
        rms = np.sqrt(np.mean(bt**2 + br**2)) if bt.size else np.nan
        ax.set_title(f"{title}: |ΔB| RMS {rms:.4g} km")
        ax.set_xlabel("ΔB_T (km)")
        ax.set_ylabel("ΔB_R (km)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{scenario.name}: B-plane dispersion at Mars")
    save(fig, "b_plane_dispersion.png")

    # Seed 001 Fig. 1: partials against the central-difference step, autodiff as reference.
    sim, law = midcourse.build(scenario)
    rows = ("B_R (m per m/s)", "B_T (m per m/s)", "t_TOF (s per m/s)")
    wrt = ("∂/∂v_x", "∂/∂v_y", "∂/∂v_z")
    eps = np.logspace(-6, 2, 33)
    k_cd, k_ad = (np.asarray(k) for k in midcourse.partials_vs_step(sim, jnp.asarray(eps)))
    scale = np.abs(k_ad).max(axis=1)
    fig, axes = plt.subplots(2, 3, figsize=(14, 7), sharex=True)
    for i in range(3):
        for j in range(3):
            axes[0, i].semilogx(eps, k_cd[:, i, j], f"C{j}.-", label=f"central diff. {wrt[j]}")
            axes[0, i].axhline(k_ad[i, j], color=f"C{j}", ls="--", lw=1, label=f"autodiff {wrt[j]}")
            departure = np.abs(k_cd[:, i, j] - k_ad[i, j]) / scale[i]
            axes[1, i].loglog(eps, np.maximum(departure, 1e-17), f"C{j}.-", label=wrt[j])
        axes[1, i].axhline(1e-6, color="k", ls=":", lw=1, label="1e-6")
        axes[0, i].set_title(rows[i])
        axes[1, i].set_xlabel("perturbation step ε (m/s)")
        axes[0, i].grid(alpha=0.3)
        axes[1, i].grid(alpha=0.3)
    axes[0, 0].set_ylabel("partial derivative")
    axes[1, 0].set_ylabel("|K_cd - K_autodiff| / max|row|")
    axes[0, 0].legend(fontsize=6)
    axes[1, 0].legend(fontsize=7)
    fig.suptitle("Partials vs step ε at the first fix (seed 001 Fig. 1); dashed: autodiff")
    save(fig, "partials_vs_epsilon.png")

    # Seed 001 Figs. 2-3 along the nominal, and the departures from autodiff.
    t_enc, t_fix = float(sim.t_encounter_s), float(sim.t_first_fix_s)
    span_days = (t_enc - t_fix) / 86400.0
    days = np.concatenate([np.linspace(span_days, 10.0, 20), np.geomspace(8.0, 1.1, 8)])
    eps_g = float(law.targeter.epsilon)
    sweep = midcourse.partials_vs_time(
        sim, jnp.asarray(t_enc - days * 86400.0), eps_g, t_enc - 86400.0
    )
    ks = {method: np.asarray(k) for method, k in sweep.items()}
    methods = (
        ("central_difference", f"central difference, ε = {eps_g:g} m/s (Fig. 2)"),
        ("stm", "state-transition matrix (Fig. 3)"),
    )
    fig, axes = plt.subplots(3, 2, figsize=(12, 10), sharex=True)
    for c, (method, title) in enumerate(methods):
        for i in range(3):
            for j in range(3):
                axes[i, c].plot(days, ks[method][:, i, j], f"C{j}.-", label=wrt[j])
                axes[i, c].plot(days, ks["autodiff"][:, i, j], f"C{j}--", lw=0.8)
            axes[i, c].set_ylabel(rows[i])
            axes[i, c].grid(alpha=0.3)
        axes[0, c].set_title(title)
        axes[2, c].set_xlabel("days to encounter")
    axes[2, 0].invert_xaxis()  # shared x: flips both columns
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Partials vs time to encounter along the nominal (dashed: autodiff)")
    save(fig, "partials_vs_time.png")

    fig, ax = plt.subplots(figsize=(9, 5))
    row_scale = np.abs(ks["autodiff"]).max(axis=2, keepdims=True)
    for method, label in (
        ("central_difference", f"central difference, ε = {eps_g:g} m/s"),
        ("stm", "STM to the periapsis epoch (gnc_jax targeter)"),
        ("stm_fixed_epoch", "STM to a fixed end epoch E-1 d, two-body Q there (paper)"),
    ):
        departure = (np.abs(ks[method] - ks["autodiff"]) / row_scale).max(axis=(1, 2))
        ax.semilogy(days, np.maximum(departure, 1e-17), ".-", label=label)
    ax.invert_xaxis()
    ax.set_xlabel("days to encounter")
    ax.set_ylabel("max |K - K_autodiff| / max|row|")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title("Departure of the sensitivity methods from autodiff along the nominal")
    save(fig, "sensitivity_departure.png")

    # Seed 001 Fig. 4: Δv per correction.
    columns = [c for c in runs if c.startswith("dv_per_fix_mps_")]
    columns.sort(key=lambda c: int(c.rsplit("_", 1)[1]))
    per_fix = np.stack([runs[c] for c in columns], axis=1)
    fix_epochs = t_fix + float(sim.fix_interval_s) * np.arange(per_fix.shape[1])
    fix_days = (t_enc - fix_epochs) / 86400.0
    width = 0.8 * float(sim.fix_interval_s) / 86400.0 if per_fix.shape[1] > 1 else 5.0
    fig, ax = plt.subplots(figsize=(10, 4.5))
    ax.bar(fix_days, per_fix[0], width=width, color="C0", alpha=0.7, label="run 0")
    if ok.sum() > 1:
        ax.plot(fix_days, per_fix[ok].mean(axis=0), "C3o-", ms=3, label=f"mean, {ok.sum()} runs")
    if np.any(per_fix[0] > 0):
        ax.set_yscale("log")
    ax.invert_xaxis()
    ax.set_xlabel("days to encounter")
    ax.set_ylabel("Δv per correction (m/s)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    total = summary.get("dv_mean_mps", np.nan)
    ax.set_title(f"{scenario.name}: Δv per correction (seed 001 Fig. 4); total {total:.4g} m/s")
    save(fig, "dv_per_fix.png")
    return files


def _capsule_figures(summary, runs, scenario, out: pathlib.Path) -> list[pathlib.Path]:
    """Seed 003 Figs. 4-6 (predictions, altitude-range fan, chute scatter), bank histories and
    the chute miss against the dispersed L/D."""
    from .montecarlo import simulate_traces

    plt = _plt()
    files = []

    save = _saver(plt, out, files)

    ok = runs["status"] == Status.ok
    n_ok = int(ok.sum())
    dr, cr = runs["downrange_err_km"][ok], runs["crossrange_err_km"][ok]
    paper = scenario.paper

    # Fig. 6: chute-deploy points with the 1-sigma and 3-sigma ellipses.
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.scatter(cr, dr, s=5, alpha=0.5, label=f"chute deploy ({n_ok} runs)")
    ax.plot(0, 0, "r+", ms=14, mew=2, label="target")
    if n_ok > 2:
        xy = np.stack([cr, dr], axis=1)
        for k, style in ((1, "-"), (3, "--")):
            e = _ellipse_xy(xy.mean(axis=0), np.cov(xy.T), k)
            ax.plot(e[0], e[1], "k" + style, lw=1, label=f"{k}σ ellipse")
    ax.add_patch(
        plt.Rectangle((-2.5, -2.5), 5, 5, fill=False, ec="C2", lw=1, label="±2.5 km (issue)")
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
    ax.set_title(
        f"{scenario.name}: chute deploy (seed 003 Fig. 6)\n"
        f"3σ downrange {summary.get('downrange_err_km_3sigma')}, "
        f"crossrange {summary.get('crossrange_err_km_3sigma')} km"
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    save(fig, "chute_scatter.png")

    # Fig. 4: predictions per trajectory and the largest count in one guidance cycle.
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
    save(fig, "predictions.png")

    # Chute miss against the dispersed lift-to-drag ratio (where the tails come from).
    d = scenario.config["dispersions"]
    z = np.stack([runs[f"dispersion_{j}"] for j in range(10)], axis=1)[ok]
    ld = (1.0 + d["cl_pct"] / 300.0 * z[:, 6]) / (1.0 + d["cd_pct"] / 300.0 * z[:, 7])
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.semilogy(ld, np.maximum(np.hypot(dr, cr), 1e-3), ".", ms=3)
    ax.axhline(2.5, color="C2", lw=1, label="2.5 km")
    ax.set_xlabel("actual L/D over nominal L/D")
    ax.set_ylabel("chute miss (km)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(f"{scenario.name}: chute miss against the dispersed L/D")
    save(fig, "miss_vs_ld.png")

    # Fig. 5: altitude against range flown for every run; bank histories of the first runs.
    every = 5
    _, tr = simulate_traces(scenario, np.flatnonzero(ok), seed=summary.get("seed"), every=every)
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
    save(fig, "altitude_range_fan.png")

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
    save(fig, "bank_histories.png")
    return files


FIGURES = {
    "impactor": _impactor_figures,
    "capsule": _capsule_figures,
    "midcourse": _midcourse_figures,
}


def _pn_command_panel(ax, trace, law, title):
    """Seed 004 Figs. 7-9: the continuous APN command against time, with the engine pulses."""
    t_h = trace.t_s / 3600.0
    r = trace.r_m
    u = -r / np.linalg.norm(r, axis=1, keepdims=True)
    planar = np.allclose(r[:, 2], 0.0)
    if planar:  # signed, as in the paper: the component along the LOS turned by +90 deg
        a = trace.command_mps2[:, 0] * -u[:, 1] + trace.command_mps2[:, 1] * u[:, 0]
        label = "A (eq. 11), in-plane normal to the LOS"
    else:
        a = np.linalg.norm(trace.command_mps2, axis=1)
        label = "|A| (eq. 11)"
    on = trace.engine_on > 0.5
    ax.plot(t_h, a, lw=0.8, color="C0", label=label)
    a_on, a_off = float(law.a_on_mps2), float(law.a_off_mps2)
    for sign in (1, -1) if planar else (1,):
        ax.axhline(sign * a_on, color="C3", ls="--", lw=0.8)
        ax.axhline(sign * a_off, color="C2", ls=":", lw=0.8)
    ax.plot([], [], "C3--", lw=0.8, label=f"a_on = {a_on:.3g} m/s²")
    ax.plot([], [], "C2:", lw=0.8, label=f"a_off = {a_off:.3g} m/s²")
    ax.set_yscale("symlog", linthresh=a_off)
    ymax = max(np.abs(a).max(), a_on) * 1.5
    ax.set_ylim(-ymax if planar else 0.0, ymax)
    ax.vlines(t_h[on], -ymax if planar else 0.0, ymax, color="C1", alpha=0.25, lw=0.6)
    ax.plot([], [], color="C1", alpha=0.5, label=f"engine pulses ({on.sum()} steps)")
    ax.set_ylabel("command (m/s²)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=7)


def _pn_figures(summary, runs, scenario, out: pathlib.Path) -> list[pathlib.Path]:
    """Seed 004: command histories (Figs. 7-9), B-plane misses (Fig. 10), Δv and firings."""
    from .montecarlo import SYSTEMS, simulate_one

    plt = _plt()
    ok = runs["status"] == Status.ok
    files = []

    save = _saver(plt, out, files)

    # Run 0 of the study, then the three laws of Table 3 error-free from the same scenario.
    _, law = SYSTEMS["pn"].build(scenario)
    _, trace = simulate_one(scenario, index=0, seed=summary.get("seed"))
    fig, ax = plt.subplots(figsize=(10, 4.5))
    g = scenario.config["guidance"]
    _pn_command_panel(ax, trace, law, f"{scenario.name}, run 0: N0 = {g['n0']:g}, k = {g['k']:g}")
    ax.set_xlabel("mission time (h)")
    save(fig, "command_trace.png")

    ideal = {"navigation.model": "perfect", "errors.attitude_urad": 0.0}
    ideal["navigation.knowledge_position_km"] = [0.0, 0.0, 0.0]
    ideal["navigation.knowledge_velocity_mps"] = 0.0
    cases = (
        ("variable N (N0 = 8, k = 2), Fig. 7", 8.0, 2.0),
        ("constant N = 3, Fig. 8", 3.0, 0.0),
        ("constant N = 8, Fig. 9", 8.0, 0.0),
    )
    fig, axes = plt.subplots(3, 1, figsize=(10, 10), sharex=True)
    for ax, (title, n0, k) in zip(axes, cases):
        sc = scenario.with_overrides({**ideal, "guidance.n0": n0, "guidance.k": k})
        o, tr = simulate_one(sc, index=0, seed=0)
        _, law_k = SYSTEMS["pn"].build(sc)
        _pn_command_panel(
            ax,
            tr,
            law_k,
            f"{title}: {int(o.firings)} firings, Δv {float(o.dv_mps):.2f} m/s, "
            f"miss {float(o.miss_m):.2f} m (error-free)",
        )
    axes[-1].set_xlabel("mission time (h)")
    save(fig, "command_laws.png")

    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    bt, br = runs["miss_t_m"][ok], runs["miss_r_m"][ok]
    ax.scatter(bt, br, s=4, alpha=0.5, label=f"impacts ({ok.sum()})")
    ax.plot(0, 0, "r+", ms=14, mew=2, label="target centre")
    if ok.sum() > 2 and np.std(br) > 0:
        cov = np.cov(np.stack([bt, br]))
        for kk, style in ((1, "-"), (3, "--")):
            xy = _ellipse_xy(np.array([bt.mean(), br.mean()]), cov, kk)
            ax.plot(xy[0], xy[1], "k" + style, lw=1, label=f"{kk}σ ellipse")
    ax.set_xlabel("B·T (m)")
    ax.set_ylabel("B·R (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(
        f"{scenario.name}: B-plane misses (seed 004 Fig. 10)\n"
        f"RMS {summary.get('miss_rms_m', np.nan):.1f} m, "
        f"max {summary.get('miss_max_m', np.nan):.1f} m"
    )
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    save(fig, "b_plane.png")

    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(14, 3.8))
    a1.hist(runs["miss_m"][ok], bins=40, color="C2")
    a1.set_xlabel("miss (m)")
    a1.set_ylabel("runs")
    a2.hist(runs["dv_mps"][ok], bins=40, color="C0")
    a2.axvline(summary.get("dv_mean_mps", np.nan), color="k", ls="--", label="mean")
    a2.set_xlabel("total Δv (m/s)")
    a2.legend()
    f = runs["firings"][ok].astype(int)
    counts = np.bincount(f) if f.size else np.zeros(1)
    a3.bar(np.arange(len(counts)), counts, color="C1")
    a3.set_xlabel("firings (pulse trains)")
    fig.suptitle(f"{scenario.name}: miss, Δv and firings ({ok.sum()} runs)")
    save(fig, "dv_firings.png")
    return files


FIGURES["pn"] = _pn_figures


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
