"""The midcourse system's contract: autonomous B-plane targeting on an interplanetary transfer
(seed 001).

Truth propagation, navigation and execution errors are in
:mod:`gnc_jax.systems.midcourse.simulation`, the nominal transfer and the simulation data in
:mod:`~gnc_jax.systems.midcourse.nominal` and :mod:`~gnc_jax.systems.midcourse.build`, the
sensitivity figures' partials in :mod:`~gnc_jax.systems.midcourse.partials`; the correction
rule and its Newton targeter in :mod:`gnc_jax.guidance.midcourse`; the scenario
parameters in :mod:`gnc_jax.systems.midcourse.params`, their cross-field checks in
:mod:`gnc_jax.systems.midcourse.schema`.
"""

import pathlib
from typing import Any, ClassVar

import jax.numpy as jnp
import numpy as np

from ..._status import Status, shown_run
from ...constants import SECONDS_PER_DAY
from ...guidance.midcourse import AbstractMidcourseGuidance
from ...plotting import pyplot, saver
from ...statistics import std
from ..base import AbstractSystem, register_system
from . import build as midcourse_build
from . import params as midcourse_params
from . import partials as midcourse_partials
from . import schema as midcourse_scenario
from . import simulation as midcourse_sim
from .sources import BUDGET_METRICS, ERROR_SOURCES, SOURCE_GROUPS


def _midcourse_statistics(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    if not ok.any():
        return {}
    rms = lambda x: float(np.sqrt(np.mean(x**2)))
    b, tof = o["b_err_m"][ok] / 1e3, np.abs(o["tof_err_s"][ok])
    b0, tof0 = o["b0_err_m"][ok] / 1e3, np.abs(o["tof0_err_s"][ok])
    dv, count = o["dv_mps"][ok], o["corrections"][ok]
    per_fix = o["dv_per_fix_mps"][ok]
    later = per_fix[:, 1:][per_fix[:, 1:] > 0.0]
    return dict(
        b_err_km_rms=rms(b),
        b_err_km_max=float(np.max(b)),
        tof_err_s_rms=rms(tof),
        tof_err_s_max=float(np.max(tof)),
        dv_mean_mps=float(np.mean(dv)),
        corrections_mean=float(np.mean(count)),
        goal_met=int(np.sum(o["goal_met"][ok])),
        goal_met_pct=float(100.0 * np.mean(o["goal_met"][ok])),
        b_err_r_km_std=std(o["b_err_r_m"][ok] / 1e3),
        b_err_t_km_std=std(o["b_err_t_m"][ok] / 1e3),
        tof_err_s_std=std(o["tof_err_s"][ok]),
        b0_err_km_rms=rms(b0),
        b0_err_km_max=float(np.max(b0)),
        b0_err_r_km_std=std(o["b0_err_r_m"][ok] / 1e3),
        b0_err_t_km_std=std(o["b0_err_t_m"][ok] / 1e3),
        tof0_err_s_rms=rms(tof0),
        dv_max_mps=float(np.max(dv)),
        dv_first_mean_mps=float(np.mean(o["dv_first_mps"][ok])),
        dv_ref_mean_mps=float(np.mean(o["dv_ref_mps"][ok])),
        dv_increase_pct_mean=float(np.mean(o["dv_increase_pct"][ok])),
        # of the corrections after the first fix's; None when no run made one
        later_dv_max_mps=float(np.max(later)) if later.size else None,
        later_dv_below_0p2_pct=float(100.0 * np.mean(later < 0.2)) if later.size else None,
        corrections_max=int(np.max(count)),
        correction_every_fix_pct=float(100.0 * np.mean(count == per_fix.shape[1])),
        iterations_mean=float(np.mean(o["iterations"][ok][count > 0])) if np.any(count) else 0.0,
        # over every run: a run with a fix handed to the ground reads out_of_domain
        ground_calls_total=int(np.sum(o["ground_calls"])),
    )


ROWS = ("B_R (m per m/s)", "B_T (m per m/s)", "t_TOF (s per m/s)")
WRT = ("∂/∂v_x", "∂/∂v_y", "∂/∂v_z")


def _b_plane_dispersion(plt, runs, ok, scenario):
    goal_km = scenario.config["goal"]["b_km"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, prefix, title in ((axes[0], "b0", "before correction"), (axes[1], "b", "after")):
        bt, br = runs[f"{prefix}_err_t_m"][ok] / 1e3, runs[f"{prefix}_err_r_m"][ok] / 1e3
        ax.scatter(bt, br, s=6, alpha=0.6, label=f"runs ({ok.sum()})")
        goal = plt.Circle((0, 0), goal_km, fill=False, color="r", label=f"goal {goal_km:g} km")
        ax.add_patch(goal)
        if bt.size:
            ax.set_title(f"{title}: |ΔB| RMS {np.sqrt(np.mean(bt**2 + br**2)):.4g} km")
        else:
            ax.set_title(f"{title}: no ok run ({len(ok)} failed)")
        ax.set_xlabel("ΔB_T (km)")
        ax.set_ylabel("ΔB_R (km)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{scenario.name}: B-plane dispersion at Mars")
    return fig


def _partials_vs_epsilon(plt, sim):
    """Seed 001 Fig. 1: partials against the central-difference step, autodiff as reference."""
    rows, wrt = ROWS, WRT
    eps = np.logspace(-6, 2, 33)
    k_cd, k_ad = (np.asarray(k) for k in midcourse_partials.partials_vs_step(sim, jnp.asarray(eps)))
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
    return fig


def _partials_vs_time(plt, sim, eps_g):
    """Seed 001 Figs. 2-3 along the nominal, and the departures of the methods from autodiff."""
    t_enc, t_fix = float(sim.t_encounter_s), float(sim.t_first_fix_s)
    span_days = (t_enc - t_fix) / SECONDS_PER_DAY
    days = np.concatenate([np.linspace(span_days, 10.0, 20), np.geomspace(8.0, 1.1, 8)])
    sweep = midcourse_partials.partials_vs_time(
        sim, jnp.asarray(t_enc - days * SECONDS_PER_DAY), eps_g, t_enc - SECONDS_PER_DAY
    )
    ks = {method: np.asarray(k) for method, k in sweep.items()}
    wrt, rows = WRT, ROWS
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
    departure_figure = _sensitivity_departure(plt, days, ks, eps_g)
    return fig, departure_figure


def _sensitivity_departure(plt, days, ks, eps_g):
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
    return fig


def _dv_per_fix(plt, summary, runs, ok, scenario, sim):
    """Seed 001 Fig. 4: Δv per correction."""
    t_enc, t_fix = float(sim.t_encounter_s), float(sim.t_first_fix_s)
    columns = [c for c in runs if c.startswith("dv_per_fix_mps_")]
    columns.sort(key=lambda c: int(c.rsplit("_", 1)[1]))
    per_fix = np.stack([runs[c] for c in columns], axis=1)
    fix_epochs = t_fix + float(sim.fix_interval_s) * np.arange(per_fix.shape[1])
    fix_days = (t_enc - fix_epochs) / SECONDS_PER_DAY
    width = 0.8 * float(sim.fix_interval_s) / SECONDS_PER_DAY if per_fix.shape[1] > 1 else 5.0
    shown, label = shown_run(runs["status"])
    fig, ax = plt.subplots(figsize=(10, 4.5))
    ax.bar(fix_days, per_fix[shown], width=width, color="C0", alpha=0.7, label=label)
    if ok.sum() > 1:
        ax.plot(fix_days, per_fix[ok].mean(axis=0), "C3o-", ms=3, label=f"mean, {ok.sum()} runs")
    if np.any(per_fix[shown] > 0):
        ax.set_yscale("log")
    ax.invert_xaxis()
    ax.set_xlabel("days to encounter")
    ax.set_ylabel("Δv per correction (m/s)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    total = summary.get("dv_mean_mps")
    total = "no ok run" if total is None else f"total {total:.4g} m/s"
    ax.set_title(f"{scenario.name}: Δv per correction (seed 001 Fig. 4); {total}")
    return fig


def midcourse_figures(summary, runs, scenario, out: pathlib.Path) -> list[pathlib.Path]:
    """B-plane dispersion, seed 001 Figs. 1-4 and where the sensitivity methods depart."""
    plt = pyplot()
    ok = runs["status"] == Status.ok
    files = []
    save = saver(plt, out, files)
    save(_b_plane_dispersion(plt, runs, ok, scenario), "b_plane_dispersion.png")
    sim, _ = MidcourseSystem().build(scenario)
    save(_partials_vs_epsilon(plt, sim), "partials_vs_epsilon.png")
    # Fig. 2's step: the scenario's central-difference step, whatever method it flies
    by_time, departure = _partials_vs_time(
        plt, sim, float(scenario["guidance.autonomous.epsilon_mps"])
    )
    save(by_time, "partials_vs_time.png")
    save(departure, "sensitivity_departure.png")
    save(_dv_per_fix(plt, summary, runs, ok, scenario, sim), "dv_per_fix.png")
    return files


# The midcourse cost model, in dopri8 stage evaluations. One propagation from the first fix to
# the encounter of the packaged phoenix-midcourse transfer (238 days, rtol 1e-13) takes
# _ARC_STEPS adaptive steps (diffrax's ``num_steps``), each costing _STEP_COST (dopri8: its 12
# stages; dopri5 and tsit5: measured, their steps are cheaper than their 6 stages suggest), and
# the steps grow as rtol**-0.13 when rtol tightens. A Newton iteration costs the sensitivity
# method's ``propagations`` (declared with each method). All measured by
# benchmarks/cost_midcourse_intercept.py, which also measures STEP_SECONDS (wall seconds per
# evaluation per device, 2 devices on the 2-core development machine; the model is within
# 0.8-1.9x of the measured time over solvers, tolerances, sensitivities and fix counts).
_ARC_STEPS = {"dopri8": 149.0, "dopri5": 538.0, "tsit5": 542.0}
_STEP_COST = {"dopri8": 12.0, "dopri5": 2.44, "tsit5": 2.42}
_RTOL_GROWTH = 0.13
STEP_SECONDS = 6.9e-7


def midcourse_steps(config: dict) -> float:
    """Cost of one midcourse run in dopri8 stage evaluations
    (:meth:`MidcourseSystem.steps_per_run`): propagations to the encounter (the initial and
    final predictions; per fix the law's Newton iterations and its last prediction, each as
    long as the time left to the encounter, plus the coast to the next fix), each scaled by
    rtol and at most ``max_steps`` steps."""
    p = midcourse_params.parameters(config)
    dy, nv, day = p.dynamics, p.navigation, SECONDS_PER_DAY
    law = AbstractMidcourseGuidance.laws[config["guidance"]["law"]]
    span = max(p.mission.encounter_epoch_s - p.mission.first_fix_epoch_s, day)
    steps = _ARC_STEPS[dy.solver] * (float(dy.rtol) / 1e-13) ** -_RTOL_GROWTH
    arc = min(steps, dy.max_steps) * _STEP_COST[dy.solver]  # from the first fix
    solve = law.propagations_per_fix(config["guidance"][law.law_name])
    arcs = 2.0
    if bool(p.guidance.enabled):
        interval = float(nv.fix_interval_s)
        left = sum(max(span - i * interval, day) / span for i in range(nv.fixes))
        arcs += left * solve + (nv.fixes - 1) * min(interval / span, 1.0)
        if p.errors.has_per_fix_errors():
            arcs += solve  # the error-free reference correction
    return arcs * arc


@register_system
class MidcourseSystem(AbstractSystem):
    name = "midcourse"
    error_sources = ERROR_SOURCES
    source_groups = SOURCE_GROUPS
    budget_metrics = BUDGET_METRICS
    description = "interplanetary midcourse correction by autonomous B-plane targeting"
    parameter_modules = midcourse_params.PARAMETER_MODULES
    law_family = AbstractMidcourseGuidance
    default_law = "autonomous"
    metrics = ("b_err_km_rms", "tof_err_s_rms", "dv_mean_mps", "goal_met_pct")
    paper_labels: ClassVar[dict[str, str]] = {
        "b_err_km_rms": "|ΔB| RMS (km)",
        "b_err_km_max": "|ΔB| max (km)",
        "tof_err_s_rms": "|Δt_TOF| RMS (s)",
        "tof_err_s_max": "|Δt_TOF| max (s)",
        "goal_met_pct": "goal met (% runs)",
        "corrections_mean": "corrections mean",
        "dv_increase_pct_mean": "Δv increase (%)",
        "dv_first_mean_mps": "first Δv (m/s)",
        "dv_mean_mps": "Δv mean (m/s)",
        "later_dv_below_0p2_pct": "later Δv < 0.2 m/s (%)",
        "correction_every_fix_pct": "burn every fix (% runs)",
        "iterations_mean": "Newton iterations mean",
        "b0_err_km_rms": "|ΔB| no guidance RMS (km)",
        "b0_err_r_km_std": "ΔB_R no guidance 1σ (km)",
        "b0_err_t_km_std": "ΔB_T no guidance 1σ (km)",
    }
    example = "phoenix-midcourse"
    # adaptive step control and Newton iterations amplify the batched program's rounding to
    # millimetres on a miss of tens of metres (tests/simulation/test_midcourse_sim.py)
    batch_tolerance = (1e-9, 0.05)
    test_overrides: ClassVar[dict[str, Any]] = {}

    step_seconds = STEP_SECONDS  # see _ARC_STEPS

    def steps_per_run(self, config):
        return midcourse_steps(config)

    def check(self, config):
        midcourse_scenario.check(config)

    def build(self, scenario):
        sim = midcourse_build.build(scenario)
        return sim, self.build_law(scenario.config, sim.guidance_context)

    def simulate(self, params, law, key, record=False):
        return midcourse_sim.simulate(params, law, key, record=record)

    def statistics(self, outcomes, ok):
        return _midcourse_statistics(outcomes, ok)

    def figures(self, summary, runs, scenario, out, traces=None):
        return midcourse_figures(summary, runs, scenario, out)
