"""The intercept system's contract: deep-space intercept with variable-coefficient augmented PN
and pulse firing (seed 004).

One run's loop is :mod:`gnc_jax.systems.intercept.simulation` (its truth and pulse step,
navigation, random draws and data in the modules beside it, its data built by
:mod:`gnc_jax.systems.intercept.build`); the laws in the family :mod:`gnc_jax.guidance.intercept`
(``apn``); the scenario parameters in :mod:`gnc_jax.systems.intercept.params`, their cross-field
checks in :mod:`gnc_jax.systems.intercept.schema`.
"""

import pathlib
from typing import Any, ClassVar

import numpy as np

from ..._numerics import LoopShape
from ..._status import Status, shown_run
from ...guidance.intercept.apn import PNNavigation
from ...guidance.intercept.base import AbstractInterceptGuidance
from ...plotting import ellipse_xy, pyplot, saver
from ...statistics import std
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
from . import build as intercept_build
from . import params as intercept_params
from . import schema as intercept_scenario
from . import simulation as intercept_sim
from .sources import ERROR_SOURCES, SOURCE_GROUPS


def _intercept_statistics(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    """Seed 004: miss (B-plane), total Δv, firings (pulse trains), as the impactor plus extras."""
    if not ok.any():
        return {}
    out = impact_statistics(o, ok)
    out.update(hit_statistics(o, ok))
    miss = o["miss_m"][ok]
    out.update(
        miss_std_m=std(miss),
        miss_t_std_m=std(o["miss_t_m"][ok]),
        miss_r_std_m=std(o["miss_r_m"][ok]),
        dv_min_mps=float(np.min(o["dv_mps"][ok])),
        ignitions_mean=float(np.mean(o["ignitions"][ok])),
        pulses_mean=float(np.mean(o["pulses"][ok])),
        last_firing_s_mean=float(np.mean(o["last_firing_s"][ok])),
        nav_position_error_m_rms=float(np.sqrt(np.mean(o["nav_position_error_m"][ok] ** 2))),
        images_rejected_max=int(np.max(o["images_rejected"][ok])),
        innovations_outside_mean=float(np.mean(o["innovations_outside"][ok])),
        innovations_outside_max=int(np.max(o["innovations_outside"][ok])),
        nav_lost=int(np.sum(o["status"] == Status.nav_lost)),
    )
    return out


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
    levels = law.switching_levels()  # the law's own: e.g. the APN trigger's a_on, a_off
    for (name, level), style in zip(levels.items(), ("C3--", "C2:", "C4-.", "C5-.")):
        for sign in (1, -1) if planar else (1,):
            ax.axhline(sign * level, color=style[:2], ls=style[2:], lw=0.8)
        ax.plot([], [], style, lw=0.8, label=f"{name} = {level:.3g} m/s²")
    top = max([np.abs(a).max(), *levels.values()])
    ax.set_yscale("symlog", linthresh=min(levels.values(), default=max(top, 1e-12) * 1e-3))
    ymax = top * 1.5
    ax.set_ylim(-ymax if planar else 0.0, ymax)
    ax.vlines(t_h[on], -ymax if planar else 0.0, ymax, color="C1", alpha=0.25, lw=0.6)
    ax.plot([], [], color="C1", alpha=0.5, label=f"engine pulses ({on.sum()} steps)")
    ax.set_ylabel("command (m/s²)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=7)


def estimate_pulse_trains(scenario):
    """Closed-form error-free Δv and pulse trains of an intercept scenario: its law's
    ``pulse_trains`` (seed 004 eqs. 11-12,
    :func:`gnc_jax.guidance.intercept.apn.pulse_train_estimate`) from the scenario's initial
    truth, engine and coast."""
    sim, law = InterceptSystem().build(scenario)
    p = intercept_params.parameters(scenario.config)
    y0, sc, dt_s = sim.y0, p.spacecraft, p.guidance.dt_s
    bit = float(sc.thrust_n * sc.pulse_width_s / sc.mass_kg)  # a float: the estimate is Python
    return law.pulse_trains(
        PNNavigation(y0.r, y0.v, y0.r_target),
        sim.dynamics,
        coast_s=p.guidance.coast_s,
        engine_accel_mps2=bit / dt_s,
        impulse_bit_mps=bit,
    )


_LAW_CASES = (  # seed 004 Table 3: the three laws flown error-free from the same scenario
    ("variable N (N0 = 8, k = 2), Fig. 7", 8.0, 2.0),
    ("constant N = 3, Fig. 8", 3.0, 0.0),
    ("constant N = 8, Fig. 9", 8.0, 0.0),
)


def _law_case(n0: float, k: float) -> dict:
    """Overrides of an error-free run of the APN law with ``n0`` and ``k``."""
    return {
        "navigation.model": "perfect",
        "errors.attitude_urad": 0.0,
        "navigation.knowledge_position_km": [0.0, 0.0, 0.0],
        "navigation.knowledge_velocity_mps": 0.0,
        "guidance.apn.n0": n0,
        "guidance.apn.k": k,
    }


def intercept_figures(summary, runs, scenario, out: pathlib.Path, traces) -> list[pathlib.Path]:
    """Seed 004: command histories (Figs. 7-9), B-plane misses (Fig. 10), Δv and firings."""
    plt = pyplot()
    ok = runs["status"] == Status.ok
    files = []

    save = saver(plt, out, files)

    # A run of the study (its first ok run), then the three laws of Table 3 error-free from
    # the same scenario.
    _, law = InterceptSystem().build(scenario)
    _, trace = traces["shown"]
    label = shown_run(runs["status"])[1]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    _pn_command_panel(ax, trace, law, f"{scenario.name}, {label}: {law.describe()}")
    ax.set_xlabel("mission time (h)")
    save(fig, "command_trace.png")

    fig, axes = plt.subplots(3, 1, figsize=(10, 10), sharex=True)
    for ax, (title, n0, k) in zip(axes, _LAW_CASES):
        sc = scenario.with_overrides(_law_case(n0, k))
        o, tr = traces[title]
        _, law_k = InterceptSystem().build(sc)
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
            xy = ellipse_xy(np.array([bt.mean(), br.mean()]), cov, kk)
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


def intercept_steps(config: dict) -> float:
    """Cost of one intercept run (:meth:`InterceptSystem.steps_per_run`) in guidance steps of
    the EKF loop: the guidance steps (a step with perfect navigation costs 0.4 of one), the LOS
    images (an EKF update costs 1.4 steps) and the final coast's RK4 steps, from the loop
    lengths :func:`gnc_jax.systems.intercept.build.build` is built with
    (:func:`~gnc_jax.systems.intercept.build.loop_sizes`); a float, so that a scenario
    whose loops would not fit in an integer still gets a (refusable) estimate."""
    p = intercept_params.parameters(config)
    y0, _ = intercept_build.initial_state(p)
    sizes = intercept_build.loop_sizes(p, y0)
    images, per_image = sizes.n_images, sizes.steps_per_image
    if p.navigation.model == "perfect":
        return float(0.4 * images * per_image + p.guidance.coast_steps)
    return float(images * per_image + 1.4 * images + p.guidance.coast_steps)


@register_system
class InterceptSystem(AbstractSystem):
    name = "intercept"
    error_sources = ERROR_SOURCES
    source_groups = SOURCE_GROUPS
    budget_metrics = IMPACT_BUDGET_METRICS
    description = "deep-space intercept: augmented PN with Schmitt-triggered pulse firing"
    parameter_modules = intercept_params.PARAMETER_MODULES
    law_family = AbstractInterceptGuidance
    default_law = "apn"
    metrics = ("miss_rms_m", "miss_max_m", "dv_mean_mps", "firings_mean")
    paper_labels = IMPACT_LABELS
    example = "bennu-apn"
    # a 2000 s approach, 10 km off, with proportionally smaller knowledge errors
    test_overrides: ClassVar[dict[str, Any]] = {
        "approach.impactor_position_km": [1.3417501e8, 20400.0, 0.0],
        "guidance.coast_s": 60.0,
        "navigation.knowledge_position_km": [2.0, 0.2, 0.2],
    }

    # GPU: bennu-apn on one H100 in its accelerator layout took 1.59 s for 2,000 runs (the
    # CLI, benchmarks/gpu_layout_h100.json) and 9.28 s for 200,000 (the API with the CLI's
    # defaults, benchmarks/gpu_kernels_h100.json), one chunk each: its strictly sequential
    # steps cost the same whatever the batch, 6.9 us per step of steps_per_run, plus 0.18 ns
    # per run-step.
    # CPU: bennu-apn on the 2-core development machine (2 host devices), one chunk each: 16
    # runs 0.334 s, 1000 runs 4.22 s (benchmarks/cost_calibration.py --fit): 36 ns per
    # run-step on a device plus 1.2 us per sequential step; the estimate within 1.0-1.1x of
    # the measured wall over the calibration's cases.
    step_costs: ClassVar[dict[str, StepCost]] = {
        "gpu": StepCost(1.8e-10, 6.9e-6, "bennu-apn on " + H100_LAYOUT_SOURCE),
        "cpu": StepCost(3.6e-8, 1.24e-6, "bennu-apn on " + CPU_SOURCE),
    }
    run_bytes: ClassVar[int] = 4_500  # the compiled batch's bytes per run on the CPU (4,484)
    # Latency-bound on a GPU (91,200 sequential steps for bennu-apn whatever the batch): 8
    # control steps per scan trip instead of 4 took 2,000 runs from 2.57 s to 2.29 s on an H100
    # (16: 2.24 s, for twice the compile time); benchmarks/gpu_loops.py --sweep. Its 3-vectors
    # by component: no stack and transpose kernels per step (benchmarks/gpu_kernels.py).
    accelerator_loop_shape: ClassVar[Any] = LoopShape(
        fence=False, unroll=8, early_exit=False, components=True
    )

    def steps_per_run(self, config):
        return intercept_steps(config)

    def check(self, config):
        intercept_scenario.check(config)

    def build(self, scenario):
        sim = intercept_build.build(scenario)
        return sim, self.build_law(scenario.config, sim.context)

    def simulate(self, params, law, key, record=False):
        return intercept_sim.simulate(params, law, key, record=record)

    def smooth_objective(self, outcomes):
        return impact_objective(outcomes)

    def statistics(self, outcomes, ok):
        return _intercept_statistics(outcomes, ok)

    def figure_traces(self, summary, runs, scenario):
        cases = {
            t: TraceRequest((0,), _law_case(n0, k), seed=0, single=True) for t, n0, k in _LAW_CASES
        }
        shown = shown_run(runs["status"])[0]
        return {"shown": TraceRequest((shown,), single=True), **cases}

    def figures(self, summary, runs, scenario, out, traces=None):
        return intercept_figures(summary, runs, scenario, out, traces)
