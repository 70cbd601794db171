"""The impactor system's contract: a small-body impactor's terminal phase (seeds 000 and 002).

One closed-loop run (truth, camera, EKF, guidance, engine) is
:mod:`gnc_jax.systems.impactor.simulation`, its data built by :mod:`gnc_jax.systems.impactor.build`;
the laws in the family :mod:`gnc_jax.guidance.impactor` (``los``, ``predictive``, ``pn`` and any
law registered into it); the scenario fields in :mod:`gnc_jax.systems.impactor.params` and their
cross-field checks in :mod:`gnc_jax.systems.impactor.schema`. This file ties them together,
with the summary statistics and the report figures.
"""

import dataclasses
import pathlib
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ..._numerics import LoopShape, RareLayout
from ..._status import Status, shown_run
from ...geometry.bplane import b_plane_frame
from ...geometry.ellipse import ellipse_probability
from ...geometry.silhouette import focusing_factor, silhouette_matrix, silhouette_ratio
from ...guidance.impactor.base import AbstractImpactorGuidance
from ...navigation.camera import camera_attitude, los_angles
from ...navigation.centroid import extract_centroid
from ...navigation.measurements import AbstractMeasurement, measurement_class
from ...navigation.render import choose_binning, phase_offset_tangent, render_frame, tangent_to_roi
from ...plotting import ellipse_xy, pyplot, saver
from ..base import (
    CPU_SOURCE,
    H100_LAYOUT_SOURCE,
    AbstractSystem,
    StepCost,
    TraceRequest,
    register_system,
)
from ..impact import (
    IMPACT_BUDGET_METRICS,
    IMPACT_LABELS,
    hit_statistics,
    impact_objective,
    impact_statistics,
)
from . import build as impactor_build
from . import schema as impactor_scenario
from . import simulation as impactor_sim
from .params import PARAMETER_MODULES, ImpactorParams, timeline
from .sources import ERROR_SOURCES, SOURCE_GROUPS


def _impactor_statistics(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    """The impactor statistics (miss, hit probability) plus those of the seed 000/002
    navigation front ends."""
    out = impact_statistics(o, ok)
    if out:
        out.update(hit_statistics(o, ok))
        out.update(
            los_error_rms_urad_mean=float(np.mean(o["los_error_rms_urad"][ok])),
            images_rejected_max=int(np.max(o["images_rejected"][ok])),
            images_rejected_mean=float(np.mean(o["images_rejected"][ok])),
            innovations_outside_mean=float(np.mean(o["innovations_outside"][ok])),
            innovations_outside_max=int(np.max(o["innovations_outside"][ok])),
            nav_lost=int(np.sum(o["status"] == Status.nav_lost)),
        )
    return out


def _b_plane_points(plt, summary, runs, ok, scenario):
    """Impact points in the B-plane with their 1σ and 3σ ellipses (seed 000 eq. 17)."""
    sim = impactor_build.build(scenario)
    aim = np.asarray(sim.context.aim_final_m)
    b = np.stack([runs["b_t_m"][ok], runs["b_r_m"][ok]], axis=1)

    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.scatter(b[:, 0] - aim[0], b[:, 1] - aim[1], s=4, alpha=0.5, label=f"impacts ({ok.sum()})")
    ax.plot(0, 0, "r+", ms=14, mew=2, label=f"aim point ({aim[0]:g}, {aim[1]:g}) m")
    if len(b) > 2:
        mean = b.mean(axis=0) - aim
        cov = np.cov(b.T)
        for k, style in ((1, "-"), (3, "--")):
            xy = ellipse_xy(mean, cov, k)
            p = float(ellipse_probability(k))
            ax.plot(xy[0], xy[1], "k" + style, lw=1, label=f"{k}σ ellipse (P = {p:.3f})")
    shadow = np.asarray(impactor_sim.capture_silhouette(sim))
    xy = ellipse_xy(-aim, shadow, 1)
    ax.plot(xy[0], xy[1], "C2-", lw=1.5, label="target silhouette (hit inside)")
    ax.set_xlabel("B·T − aim (m)")
    ax.set_ylabel("B·R − aim (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(
        f"{scenario.name}: B-plane impact points\n"
        f"miss RMS {summary.get('miss_rms_m', np.nan):.1f} m, "
        f"max {summary.get('miss_max_m', np.nan):.1f} m; "
        f"P(hit) {summary.get('hit_probability', np.nan):.3f} "
        "[{:.3f}, {:.3f}] (95 %)".format(*summary.get("hit_probability_ci95", [np.nan] * 2))
    )
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _dv_and_firings(plt, summary, runs, ok, scenario):
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
    return fig


def _engine_trace(plt, trace, scenario, law, shown):
    """The engine of the run ``shown`` names against the law's own curves (for the LOS law its
    switching curves, seed 000 Fig. 3), as the law states them (``state_curves``)."""
    t = trace.t_s
    fig, ax = plt.subplots(figsize=(9, 4.5))
    curves = law.state_curves(trace.law_state)
    if curves:
        for label, values in curves.items():
            ax.semilogy(t, values, lw=1, label=label)
        first = np.asarray(next(iter(curves.values())))
        ax.set_ylabel("law state")
        lo = np.nanmin(np.where(first > 0, first, np.nan))
        ax.set_ylim(max(lo, 1e-12), None)
        title = f"the law's curves ({law.describe()}), {shown}"
    else:
        ax.set_ylabel("throttle")
        title = f"burns of the predictive law, {shown}"
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
    return fig


def impactor_figures(summary, runs, scenario, out: pathlib.Path, traces) -> list[pathlib.Path]:
    """B-plane impact points with 1σ/3σ ellipses, Δv and firings, and the engine trace (seed
    000 Fig. 3 for the LOS law) and rendered frames (seed 002 Fig. 7) of the study's first
    ``ok`` run (:func:`~gnc_jax._status.shown_run`)."""
    plt = pyplot()
    ok = runs["status"] == Status.ok
    files = []
    save = saver(plt, out, files)
    save(_b_plane_points(plt, summary, runs, ok, scenario), "b_plane.png")
    save(_dv_and_firings(plt, summary, runs, ok, scenario), "dv_firings.png")
    _, trace = traces["shown"]
    label = shown_run(runs["status"])[1]
    _, law = ImpactorSystem().build(scenario)
    save(_engine_trace(plt, trace, scenario, law, label), "engine_trace.png")
    files.append(_centroid_frames_figure(scenario, trace, out, label))
    return files


def _centroid_frames_figure(scenario, trace, out: pathlib.Path, label: str) -> pathlib.Path:
    """Seed 002 Fig. 7: rendered frames of the run ``label`` names with the extracted centroid
    marked.

    Frames at four mission times along that run's true trajectory, rendered by the image front
    end with the scenario's camera and target (camera pointed at the navigation estimate, no
    attitude error, binning for the filter's measurement noise ``navigation.model_*``),
    centroided by the seed 002 pipeline. Shown for every impactor study: with
    ``navigation.measurement = "noise"`` it illustrates what the noise model stands for.
    """

    plt = pyplot()
    sim = impactor_build.build(scenario)
    cam, tgt = sim.camera, sim.target
    t_end = float(trace.t_s[-1])
    times = [0.0, 0.5 * t_end, 0.85 * t_end, t_end - 660.0]  # the last: ~12 min before impact
    model = sim.noise_model  # the filter's measurement noise, which the loop's binning sees
    pointing = float(np.hypot(model.image_processing_rad, model.attitude_noise_rad))
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
    fig.suptitle(
        f"{scenario.name}, {label}: rendered ROI frames and extracted centroids (seed 002 Fig. 7)"
    )
    path = out / "centroid_frames.png"
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path


"""How the published miss, Δv and firing metrics of an impact read (impactor and intercept)."""


@register_system
class ImpactorSystem(AbstractSystem):
    name = "impactor"
    error_sources = ERROR_SOURCES
    source_groups = SOURCE_GROUPS
    budget_metrics = IMPACT_BUDGET_METRICS
    description = "small-body impactor terminal guidance: optical navigation, EKF, engine"
    parameter_modules = PARAMETER_MODULES
    law_family = AbstractImpactorGuidance
    default_law = "los"
    metrics = (
        "miss_rms_m",
        "miss_max_m",
        "dv_mean_mps",
        "dv_max_mps",
        "firings_mean",
        "hit_probability",
    )
    paper_labels: ClassVar[dict[str, str]] = {
        **IMPACT_LABELS,
        "los_error_rms_urad_mean": "LOS meas. error RMS (µrad)",
    }
    envelope_metrics: ClassVar[dict[str, str]] = {
        "hit_probability": "hit probability",
        "dv_mean_mps": "Δv mean (m/s)",
        "miss_rms_m": "miss RMS (m)",
        "failed_fraction": "failed fraction",
    }
    example = "deep-impact-los"
    # a 15-minute approach: the whole chain (images, EKF, both laws, retarget, cut-off) in a
    # tenth of the steps; the last predictive burn 100 s before impact, as the paper's last is
    # 420 s before it on a 2-hour approach (with a perfect sensor it then lands within a metre)
    test_overrides: ClassVar[dict[str, Any]] = {
        "approach.position_km": [9180.0, 0.0, 0.0],
        "guidance.retarget_tgo_s": 300.0,
        "guidance.predictive.burn_times_s": [150.0, 450.0, 660.0, 800.0],
    }

    # Cost model (benchmarks/cost_calibration.py): steps_per_run counts an image as
    # IMAGE_STEPS control steps with the Gaussian front end and, with rendered frames, more in
    # proportion to the rays traced and the labelling sweeps; step_costs gives each platform's
    # seconds per run-step and per sequential step.
    # Measured on deep-impact-los, 2 devices (benchmarks/closed_loops.py): 1024 runs per call
    # (512 per device) 427 us per run, 4096 (2048 per device) 334, 8192 350; on one device
    # 512 runs 635 us, 1024-2048 560, 4096 578 (a device's batch below ~1000 runs pays the
    # per-operation overhead of its ~40 kernels per step, above ~2000 its working set
    # outgrows the 1 MB L2 cache).
    chunk_per_device: ClassVar[int] = 2048
    # The 15 control steps of an image interval unrolled 5 times per scan trip: measured 5 %
    # faster on the CPU (deep-impact-los, 2,000 runs on 2 cores), outcomes equal to the last bit.
    cpu_loop_shape: ClassVar[Any] = LoopShape(fence=True, unroll=5, early_exit=True)
    # A large study on the CPU coasts each image interval on every run, then flies it again
    # on the full path for the runs whose engine fired, gathered into 1/32 of the lanes
    # (LoopShape.rare, image_step); every outcome equal to the last bit. deep-impact-los on
    # 2 cores, 2 host devices, 100,000 runs in chunks of 2,000 per device: 11.7 s instead of
    # 14.1 s, compiled in 9.9 s instead of 6.8 (40,960 runs: 5.2-5.3 s instead of 6.65;
    # 1,000 runs per device 18 % less, 512 13 %, 256 no gain beyond noise). The longer
    # compilation is repaid from about 130,000 runs.
    rare_layout: ClassVar[Any] = RareLayout(fraction=1 / 32, min_runs=200_000, min_lanes=512)
    # GPU: the same 5 control steps per scan trip, and the filter's mean carried through them
    # by component (the truth already is): no stack and transpose kernels per vector and step.
    # deep-impact-los, 125,000 runs in one chunk on an H100: 0.486 s in the accelerators'
    # default layout (4 steps per trip, in arrays), 0.464 s at 5 steps, 0.363 s at 4 by
    # component, 0.357 s at 5 by component, 0.399 s at 15 (no inner loop); the control
    # step's loop body 31 -> 14 kernels, the image step's 69 -> 56 (benchmarks/gpu_loops.py
    # --sweep, benchmarks/gpu_layout_h100.json); statuses equal and the outcomes equal to the
    # last bit on the GPU.
    accelerator_loop_shape: ClassVar[Any] = LoopShape(
        fence=False, unroll=5, early_exit=False, components=True
    )
    # GPU: deep-impact-los on one H100 in its accelerator layout took 0.357 s for one chunk of
    # 125,000 runs and 2.05 s for 1,000,000 in eight (the CLI's study time; the chunks queue
    # behind one another, so the latency is paid once): ~14 us per sequential step plus
    # 0.24 ns per run-step.
    # CPU: deep-impact-los on the 2-core development machine (2 host devices), one chunk each:
    # 64 runs 0.0252 s, 4096 runs 0.745 s (benchmarks/cost_calibration.py --fit): 44 ns per
    # run-step on a device plus 1.7 us per sequential step.
    step_costs: ClassVar[dict[str, StepCost]] = {
        "gpu": StepCost(2.4e-10, 1.4e-5, "deep-impact-los on " + H100_LAYOUT_SOURCE),
        "cpu": StepCost(4.4e-8, 1.7e-6, "deep-impact-los on " + CPU_SOURCE),
    }
    # the compiled batch's bytes per run on the CPU (14,980); the H100's peak was 8.0 kB per run
    run_bytes: ClassVar[int] = 15_000
    # 10,000 runs in 3 equal chunks: 1667 runs per device 396-428 us per run, 1668 261
    vector_lanes: ClassVar[int] = 8
    IMAGE_STEPS: ClassVar[float] = 2.0
    # per image, at the default camera (32 rays, ROI 32): deep-impact-los with rendered frames,
    # 40 runs on the 2-core machine, 1.1 s
    RENDER_STEPS: ClassVar[float] = 880.0

    def steps_per_run(self, config):
        p = ImpactorParams.of(config)
        times, cam = timeline(p), p.camera
        per_image = times.steps_per_image + self.IMAGE_STEPS
        if p.navigation.measurement == "image":
            rays = (cam.samples / 32) ** 2
            labelling = (cam.roi_px / 32) ** 2 * cam.label_iterations / 24
            per_image += self.RENDER_STEPS * 0.5 * (rays + labelling)
        return times.n_images * per_image - times.steps_after_cutoff + p.dynamics.coast_steps

    def schema(self):
        """The sections, with ``navigation.measurement`` choosing among the registered front
        ends (``navigation/measurements``)."""
        out = super().schema()
        field = out["navigation"]["measurement"]
        names = tuple(AbstractMeasurement.measurements)
        out["navigation"]["measurement"] = dataclasses.replace(field, choices=names)
        return out

    def check(self, config):
        impactor_scenario.check(config)
        measurement_class(config["navigation"]["measurement"]).check(config)

    def linear_unavailable(self, config):
        """The measurement front end's reason, when its derivatives are not sensitivities
        (the rendered image front end)."""
        name = config["navigation"]["measurement"]
        reason = measurement_class(name).not_differentiable
        return f"navigation.measurement = {name!r}: {reason}" if reason else None

    def warnings(self, config):
        """The law's warnings, and a final aim point outside the target's shadow (a run that
        flies it exactly misses the body: usually an aim point meant for another target)."""
        out = super().warnings(config)
        p = ImpactorParams.of(config)
        a, g = p.approach, p.guidance
        target = p.target.model(p.dynamics.sun_unit)
        shadow = silhouette_matrix(
            target.semi_axes_m, target.c_bi, b_plane_frame(a.velocity_mps, a.reference_normal)
        )
        speed = jnp.linalg.norm(jnp.asarray(a.velocity_mps))
        focusing = focusing_factor(p.dynamics.mu_target_m3s2, target.mean_radius_m, speed)
        ratio = float(silhouette_ratio(g.aim_final_m, shadow, focusing))
        if ratio >= 1.0:
            aim = ", ".join(f"{x:g}" for x in config["guidance"]["aim_final_km"])
            axes = ", ".join(f"{x:g}" for x in config["target"]["semi_axes_km"])
            out.append(
                f"guidance.aim_final_km: ({aim}) km lies outside the target's shadow in the "
                f"B-plane ({ratio:.3g} times its edge's distance along that direction; "
                f"target.semi_axes_km = [{axes}]): a run that flies it exactly misses the "
                "target, and hit_probability counts it a miss"
            )
        return out

    def build(self, scenario):
        sim = impactor_build.build(scenario)
        return sim, self.build_law(scenario.config, sim.context)

    def simulate(self, params, law, key, record=False):
        return impactor_sim.simulate(params, law, key, record=record)

    def reverse_mode(self, params, differentiated=None):
        """``params`` with the fenced computations of the closed loop given their own
        reverse-mode rules (:attr:`~.state.ImpactorSimulation.reverse_mode`)."""
        return dataclasses.replace(params, reverse_mode=True)

    def smooth_objective(self, outcomes):
        return impact_objective(outcomes)

    def statistics(self, outcomes, ok):
        return _impactor_statistics(outcomes, ok)

    def figure_traces(self, summary, runs, scenario):
        return {"shown": TraceRequest((shown_run(runs["status"])[0],), single=True)}

    def figures(self, summary, runs, scenario, out, traces=None):
        return impactor_figures(summary, runs, scenario, out, traces)
