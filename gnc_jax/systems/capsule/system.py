"""The capsule system's contract: lunar-return skip entry (seed 003).

Truth, actuator and sensors are in :mod:`gnc_jax.systems.capsule.simulation`; the law in
:mod:`gnc_jax.guidance.entry.skip_entry`, with the second-entry reference the system designs
for it in :mod:`gnc_jax.systems.capsule.reference`; the scenario parameters in
:mod:`gnc_jax.systems.capsule.params` (their cross-field checks in
:mod:`gnc_jax.systems.capsule.schema`).
"""

import math
import pathlib
import time
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ..._random import run_key
from ..._status import Status
from ...dynamics.entry import entry_state_from_conditions
from ...geometry.sphere import unit
from ...guidance.entry.base import AbstractEntryGuidance, EntryModel
from ...guidance.entry.corridor import DT_S, EntryEnvelope, track_footprints
from ...params import from_scenario, schema_of
from ...plotting import ellipse_xy, pyplot, saver
from ..base import AbstractSystem, TraceRequest, register_system
from . import simulation as capsule_sim
from .params import (
    PARAMETER_MODULES,
    CapsuleDispersions,
    Entry,
    GuidanceParams,
    SimulationParams,
    capsule_params,
    loop_counts,
)
from .reference import law_reference
from .schema import check as check_config

# Cost model of CapsuleSystem.steps_per_run: trajectory fractions of the paper scenario.
MEAN_SPEED_FRACTION = 0.58  # chute range / (flight time x entry speed): 8000 km in 1250 s at 11
FIRST_ENTRY_FRACTION = 0.16  # corrector-active first entry over the flight: (229 - 34) / 1250 s
HORIZON_FRACTION = 0.56  # mean time to the switch point from a corrector cycle over the flight
COAST_FRACTION = 0.6  # of that horizon flown in the predictor's coast steps (load < 0.02 g)
PREDICTIONS_PER_CYCLE = 2.7  # mean predictions per corrector cycle (131 over 49 cycles)
FOOTPRINT_MARGIN = 0.1  # the acceptance's margin: 10 % of a footprint's width from each edge
FOOTPRINT_TAIL = 0.005  # the dispersed footprint: the ends all but 0.5 % of the runs reach
# runs whose footprints the envelope pre-check flies at most (the first ones of the study: the
# same draws); 2000 runs estimate a fraction near 99.5 % to about 0.2 % (one sigma) at about
# 30 s per entry angle, where a 10,000-run study's every run would take minutes
FOOTPRINT_RUNS_MAX = 2000
STEP_SECONDS = 1.5e-6  # s per step and device (benchmarks/capsule_cost.py): 0.6e-6 on the paper
# scenario (256 runs in 0.69 s on 2 devices), 2.8e-6 and 3.4e-6 at 5000 and 2500 km


def _interval(x: np.ndarray) -> dict[str, Any]:
    m, s = float(np.mean(x)), float(np.std(x))
    return dict(
        mean=m,
        std=s,
        min=float(np.min(x)),
        max=float(np.max(x)),
        three_sigma=[m - 3 * s, m + 3 * s],
    )


def _capsule_statistics(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    if not ok.any():
        return {}
    out: dict[str, Any] = {
        "downrange_err_km": _interval(o["downrange_err_km"][ok]),
        "crossrange_err_km": _interval(o["crossrange_err_km"][ok]),
        "downrange_err_km_3sigma": "{:.2f} .. {:.2f}".format(
            *_interval(o["downrange_err_km"][ok])["three_sigma"]
        ),
        "crossrange_err_km_3sigma": "{:.2f} .. {:.2f}".format(
            *_interval(o["crossrange_err_km"][ok])["three_sigma"]
        ),
        # the empirical interval holding 99.73 % of the runs (what mean +- 3 std means for a
        # Gaussian), which a few heavy-tailed runs do not stretch
        **{
            f"{name}_central_99_73": "{:.2f} .. {:.2f}".format(
                *np.percentile(o[name][ok], [0.135, 99.865])
            )
            for name in ("downrange_err_km", "crossrange_err_km")
        },
        **{
            f"{name}_outside_2p5_km": int(np.sum(np.abs(o[name][ok]) > 2.5))
            for name in ("downrange_err_km", "crossrange_err_km")
        },
        # the chute-deploy 3-sigma error: the larger end of the downrange and crossrange
        # mean +- 3 std intervals (what "within +-5 km" bounds)
        "chute_3sigma_km": max(
            abs(x)
            for name in ("downrange_err_km", "crossrange_err_km")
            for x in _interval(o[name][ok])["three_sigma"]
        ),
        "load_peak_g_max": float(np.max(o["load_peak_g"][ok])),
        "load_peak_g_mean": float(np.mean(o["load_peak_g"][ok])),
        "heat_rate_peak_kw_m2_max": float(np.max(o["heat_rate_peak_kw_m2"][ok])),
        "heat_load_mj_m2_max": float(np.max(o["heat_load_mj_m2"][ok])),
        "skip_apogee_km_mean": float(np.mean(o["skip_apogee_km"][ok])),
        "predictions_mean": float(np.mean(o["predictions"][ok])),
        "predictions_max": int(np.max(o["predictions"][ok])),
        "cycle_predictions_max_mean": float(np.mean(o["cycle_predictions_max"][ok])),
        "cycle_predictions_max": int(np.max(o["cycle_predictions_max"][ok])),
        "pc_cycles_mean": float(np.mean(o["pc_cycles"][ok])),
        "corrector_failures_total": int(np.sum(o["corrector_failures"][ok])),
        "reversals_mean": float(np.mean(o["reversals"][ok])),
    }
    for name in ("switch_speed_mps", "switch_altitude_km", "switch_hdot_mps", "switch_range_km"):
        out[f"{name}_mean"] = float(np.mean(o[name][ok]))
        out[f"{name}_3sigma"] = _interval(o[name][ok])["three_sigma"]
    return out


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
    save(_predictions(plt, runs, ok, scenario), "predictions.png")
    save(_miss_against_ld(plt, runs, ok, scenario, dr, cr), "miss_vs_ld.png")
    _, tr = traces["ok_runs"]
    save(_altitude_range_fan(plt, tr, scenario), "altitude_range_fan.png")
    save(_bank_histories(plt, tr, scenario), "bank_histories.png")
    return files


def entry_envelope(config: dict, load_limit_g: float) -> EntryEnvelope:
    """The entry corridor and footprint (:class:`~gnc_jax.guidance.entry.corridor.EntryEnvelope`)
    of a validated capsule configuration's nominal vehicle, atmosphere and entry."""
    p = capsule_params(config)
    earth, vehicle, atmosphere, entry = capsule_sim.nominal_models(p)
    model = EntryModel(vehicle, earth, atmosphere)
    return EntryEnvelope(
        model, entry, p.entry.chute_altitude_m, p.simulation.max_time_s, load_limit_g
    )


@jax.jit(static_argnames=("steps",))
def _run_footprints(sim, seed, indices, steps):
    """Footprints (m) of the runs ``indices`` of root seed ``seed``: each run's dispersed
    entry state, vehicle and atmosphere (:func:`~gnc_jax.systems.capsule.simulation.dispersed_entry`
    on :func:`~gnc_jax.montecarlo.run_key`, the draws of the study), flown open loop."""

    def one(i):
        y0, vehicle, atmosphere, _ = capsule_sim.dispersed_entry(sim, run_key(seed, i))
        return EntryModel(vehicle, sim.earth, atmosphere), y0

    models, y0s = jax.vmap(one)(indices)
    start = unit(entry_state_from_conditions(sim.entry, sim.earth).r)
    return track_footprints(models, y0s, start, sim.entry.azimuth, sim.chute_altitude_m, steps)


def dispersed_footprints(config: dict, runs: int, seed: int) -> np.ndarray:
    """Each Monte Carlo run's own reachable footprint, shape (runs, 2), km: the shortest and
    longest chute range of run ``i`` (0 .. runs - 1) of a study of ``config`` with root seed
    ``seed``, flown open loop at the constant banks of the nominal footprint with its
    landing-edge bisection (:func:`~gnc_jax.guidance.entry.corridor.track_footprint`) by the run's
    own dispersed vehicle, atmosphere and entry state (the same draws as
    :func:`~gnc_jax.run_study`); NaN where no bank lands (a skip-out even with full lift
    down). Ranges along the nominal entry -> target track from the nominal entry point (the
    axis of ``entry.range_km`` and of the runs' downrange errors), so the footprints do not
    depend on ``entry.range_km``. Needs no guidance law and no reference design."""
    sim = capsule_sim.build_from_config(config)
    steps = int(math.ceil(from_scenario(SimulationParams, config).max_time_s / DT_S))
    out = _run_footprints(sim, seed, jnp.arange(runs), steps)
    return np.asarray(out) / 1e3


def reachability(footprints_km: np.ndarray, range_km: float) -> dict[str, float]:
    """Pre-check columns of a target range (km) against the runs' footprints
    (:func:`dispersed_footprints`): ``reachable_fraction`` (runs whose footprint holds the
    range), ``reachable_fraction_margin`` (and ``FOOTPRINT_MARGIN`` of its width from both
    ends), ``no_landing_fraction`` (runs no constant bank lands), and the dispersed footprint
    ``dispersed_footprint_min_km`` .. ``dispersed_footprint_max_km``: the shortest range all
    but ``FOOTPRINT_TAIL`` of the runs can fly down to and the longest they can fly out to
    (of n runs, floor(FOOTPRINT_TAIL n) may lie beyond each end: with 200 runs the
    second-largest shortest range and the second-smallest longest range; a run that lands at
    no bank counts as reaching nothing); NaN when more runs than that cannot get there."""
    lo, hi = footprints_km[:, 0], footprints_km[:, 1]
    w = hi - lo
    lands = np.isfinite(lo)
    inside = lands & (lo <= range_km) & (range_km <= hi)
    spare = FOOTPRINT_MARGIN * w
    margin = lands & (lo + spare <= range_km) & (range_km <= hi - spare)
    beyond = int(math.floor(FOOTPRINT_TAIL * len(lo) + 1e-9))  # runs allowed past an end
    q_lo = np.sort(np.where(lands, lo, np.inf))[len(lo) - 1 - beyond]
    q_hi = np.sort(np.where(lands, hi, -np.inf))[beyond]
    return dict(
        reachable_fraction=float(inside.mean()),
        reachable_fraction_margin=float(margin.mean()),
        no_landing_fraction=float((~lands).mean()),
        dispersed_footprint_min_km=float(q_lo) if np.isfinite(q_lo) else math.nan,
        dispersed_footprint_max_km=float(q_hi) if np.isfinite(q_hi) else math.nan,
    )


@register_system
class CapsuleSystem(AbstractSystem):
    name = "capsule"
    description = "lunar-return skip entry: predictor-corrector and reference tracking"
    parameter_modules = PARAMETER_MODULES
    law_family = AbstractEntryGuidance
    default_law = "skip_entry"
    metrics = ("downrange_err_km", "crossrange_err_km", "load_peak_g_max", "predictions_mean")
    paper_labels: ClassVar[dict[str, str]] = {
        "downrange_err_km_3sigma": "downrange 3σ (km)",
        "crossrange_err_km_3sigma": "crossrange 3σ (km)",
        "downrange_err_km_central_99_73": "downrange central 99.73 % (km)",
        "crossrange_err_km_central_99_73": "crossrange central 99.73 % (km)",
        "downrange_err_km_outside_2p5_km": "runs with |downrange| > 2.5 km",
        "crossrange_err_km_outside_2p5_km": "runs with |crossrange| > 2.5 km",
        "switch_speed_mps_mean": "switch V mean (m/s)",
        "switch_altitude_km_mean": "switch H mean (km)",
        "switch_hdot_mps_mean": "switch Ḣ mean (m/s)",
        "switch_range_km_mean": "switch range mean (km)",
        "predictions_mean": "predictions/traj mean",
        "predictions_max": "predictions/traj max",
        "cycle_predictions_max_mean": "max per cycle, mean",
        "cycle_predictions_max": "max per cycle, max",
    }
    example = "lunar-skip-entry"
    test_overrides: ClassVar[dict[str, Any]] = {}
    envelope_metrics: ClassVar[dict[str, str]] = {
        "chute_3sigma_km": "chute-deploy 3σ error (km, larger of downrange and crossrange)",
        "failed_fraction": "failed fraction",
        "load_peak_g_max": "peak load, largest (g)",
    }
    LOAD_LIMIT_G: ClassVar[float] = 10.0
    """Default load limit of the corridor's undershoot boundary (Apollo's lunar-return design
    limit; seed 003 gives none). ``gnc-jax envelope --load-limit-g`` changes it."""

    # measured with benchmarks/capsule_cost.py (wall s x devices / runs / steps)
    step_seconds = STEP_SECONDS
    # measured with benchmarks/capsule.py (per-run time against the chunk size): the lowest
    # per-run time is at 256 runs per device, whose working set (about 2 kB per run of
    # live buffers, the compiled chunk's temp memory) half fills a 1 MB L2 cache
    chunk_per_device = 256

    def check(self, config):
        check_config(config)

    def steps_per_run(self, config):
        """Truth RK4 steps plus the predictor's RK4 steps (one truth-step equivalent each:
        both are an RK4 step of an entry vector field), estimated from the scenario alone.

        The truth loop runs until the flight is down (about ``range / (MEAN_SPEED_FRACTION
        * entry speed)``, at most ``max_time_s``) in steps of ``dt_s``. Each corrector cycle
        of the first entry (about ``FIRST_ENTRY_FRACTION`` of the flight) makes about
        ``PREDICTIONS_PER_CYCLE`` predictions (at most ``1 + n_bracket + n_iter``), each
        integrating about ``HORIZON_FRACTION`` of the flight ahead, ``COAST_FRACTION`` of it
        in steps of ``predictor_coast_dt_s`` and the rest in steps of ``predictor_dt_s``. The
        fractions are those of the paper scenario (256 runs: flight 1250 s, guidance
        34-229 s, switch at 827 s, 2.7 predictions per cycle, 48 steps per prediction); the
        estimate is within about x3 on the off-nominal cases of
        ``benchmarks/capsule_cost.py``.
        """
        e = from_scenario(Entry, config)
        s = from_scenario(SimulationParams, config)
        clock = loop_counts(s, from_scenario(GuidanceParams, config))
        g = config["guidance"]
        law = g.get(g.get("law", self.default_law), {})
        flight_s = min(s.max_time_s, e.range_m / (MEAN_SPEED_FRACTION * float(e.speed_mps)))
        truth = math.ceil(flight_s / clock.dt_s)
        dt = law.get("predictor_dt_s", 8.0)
        dt_coast = law.get("predictor_coast_dt_s", 32.0)
        horizon_s = HORIZON_FRACTION * flight_s
        horizon = horizon_s * ((1.0 - COAST_FRACTION) / dt + COAST_FRACTION / dt_coast)
        horizon = min(horizon, law.get("predictor_max_steps", 1000))
        slots = 1 + law.get("n_bracket", 6) + law.get("n_iter", 6)
        cycles = FIRST_ENTRY_FRACTION * flight_s / clock.pc_period_s
        return float(truth + cycles * min(PREDICTIONS_PER_CYCLE, slots) * horizon)

    def envelope_check(self, configs, load_limit_g=None, runs=None, seed=None, **options):
        """Entry corridor pre-check (:mod:`gnc_jax.guidance.entry.corridor`): a cell whose entry
        flight-path angle skips out even with full lift down (overshoot) or exceeds the load
        limit even with full lift up (undershoot) is infeasible. Columns: the corridor's ends
        and the nominal vehicle's reachable footprint (constant-bank extreme chute ranges) at
        the cell's angle, whether the target lies inside it (``in_footprint``) and inside it
        with ``FOOTPRINT_MARGIN`` of its width to spare (``in_footprint_margin``).

        Given ``runs`` (and the root ``seed``, default 0; :func:`~gnc_jax.envelope` passes
        the study's), each feasible cell also gets
        the dispersed runs' own footprints (:func:`dispersed_footprints`, the study's draws;
        computed once per entry angle and vehicle, shared by the ranges) and the columns of
        :func:`reachability`, with ``footprint_runs`` (the study's first runs, at most
        ``FOOTPRINT_RUNS_MAX``) and ``footprint_s`` (wall time of the angle's footprints, s)."""
        limit = self.LOAD_LIMIT_G if load_limit_g is None else float(load_limit_g)
        field = schema_of(Entry)["fpa_deg"]  # its declared range bounds the corridor search
        out, corridors, runs_fp = [], {}, {}
        for cfg in configs:
            env = entry_envelope(cfg, limit)
            fpa = cfg["entry"]["fpa_deg"]
            # the corridor depends on everything but the angle and the target's range
            key = repr({k: v for k, v in cfg.items() if k != "entry"}) + repr(
                {k: v for k, v in cfg["entry"].items() if k not in ("fpa_deg", "range_km")}
            )
            if key not in corridors:
                corridors[key] = env.corridor(field.lo, field.hi, 0.05)
            cor = corridors[key]
            lo, hi = env.footprint(fpa)
            rng = cfg["entry"]["range_km"]
            feasible = cor.contains(fpa)
            if not feasible and not cor.undershoot_deg <= cor.overshoot_deg:
                reason = (
                    f"no entry angle in [{field.lo:g}, {field.hi:g}] deg is both captured with "
                    f"full lift down and within {limit:g} g with full lift up at this speed and "
                    "vehicle"
                )
            elif not feasible:
                side = (
                    "overshoot (skips out with full lift down)"
                    if fpa > cor.overshoot_deg
                    else (f"undershoot (above {limit:g} g with full lift up)")
                )
                reason = (
                    f"outside the entry corridor {cor.undershoot_deg:.2f} .. "
                    f"{cor.overshoot_deg:.2f} deg: {side}"
                )
            else:
                reason = ""
            w = hi - lo
            columns = dict(
                corridor_undershoot_deg=cor.undershoot_deg,
                corridor_overshoot_deg=cor.overshoot_deg,
                load_limit_g=limit,
                footprint_min_km=lo,
                footprint_max_km=hi,
                in_footprint=bool(lo <= rng <= hi),
                in_footprint_margin=bool(
                    lo + FOOTPRINT_MARGIN * w <= rng <= hi - FOOTPRINT_MARGIN * w
                ),
            )
            if runs is not None and feasible:
                s = 0 if seed is None else int(seed)
                # the runs' footprints depend on everything but the target's range
                fkey = repr(
                    {k: v for k, v in cfg.items() if k != "entry"}
                    | {"entry": {k: v for k, v in cfg["entry"].items() if k != "range_km"}}
                ) + repr((runs, s))
                n_fp = min(int(runs), FOOTPRINT_RUNS_MAX)
                if fkey not in runs_fp:
                    t0 = time.perf_counter()
                    fp = dispersed_footprints(cfg, n_fp, s)
                    runs_fp[fkey] = fp, time.perf_counter() - t0
                fp, wall = runs_fp[fkey]
                columns.update(reachability(fp, rng), footprint_runs=n_fp, footprint_s=wall)
            out.append(dict(feasible=feasible, reason=reason, columns=columns))
        return out

    def envelope_overlay(self, ax, envelope, x_key, y_key):
        """The entry corridor (lines at its ends) when an axis is ``entry.fpa_deg``, and the
        reachable footprint (shortest and longest constant-bank chute range against the
        angle) when the other is ``entry.range_km``: the nominal vehicle's and, when the
        pre-check computed it, the dispersed runs' (:func:`reachability`, at the grid's
        angles; NaN where more than ``FOOTPRINT_TAIL`` of the runs do not get there)."""
        cells = envelope.cells
        if "entry.fpa_deg" not in (x_key, y_key) or not cells:
            return
        vertical = x_key == "entry.fpa_deg"
        line = ax.axvline if vertical else ax.axhline
        c0 = cells[0]
        for name, style in (("corridor_overshoot_deg", "--"), ("corridor_undershoot_deg", ":")):
            v = c0.get(name)
            if v is not None and np.isfinite(v):
                line(v, color="r", ls=style, lw=1.5, label=name.replace("_", " "))
        other = y_key if vertical else x_key
        if other != "entry.range_km":
            return
        fpas = np.asarray(envelope.axes["entry.fpa_deg"], float)
        dense = np.linspace(fpas.min(), fpas.max(), 25)
        limit = c0.get("load_limit_g", self.LOAD_LIMIT_G)
        fp = entry_envelope(envelope.scenario.config, limit).footprints(dense)
        lim = ax.get_ylim() if vertical else ax.get_xlim()
        for k, name in ((0, "footprint: shortest range"), (1, "footprint: longest range")):
            xy = (dense, fp[:, k]) if vertical else (fp[:, k], dense)
            ax.plot(*xy, "m-" if k else "m--", lw=2, label=name)
        # the dispersed runs' footprint (the pre-check's columns, one per grid angle)
        by_fpa = {}
        for c in cells:
            if "dispersed_footprint_min_km" in c:
                by_fpa[c["entry.fpa_deg"]] = (
                    c["dispersed_footprint_min_km"],
                    c["dispersed_footprint_max_km"],
                )
        if by_fpa:
            a = np.array(sorted(by_fpa))
            ends = np.array([by_fpa[x] for x in a], float)
            tail = f"{100 * (1 - FOOTPRINT_TAIL):g} % of runs"
            for k, name in ((0, "shortest"), (1, "longest")):
                xy = (a, ends[:, k]) if vertical else (ends[:, k], a)
                ax.plot(
                    *xy,
                    "-o" if k else "--o",
                    color="C1",
                    lw=2,
                    ms=4,
                    label=f"dispersed footprint ({tail}): {name} range",
                )
        (ax.set_ylim if vertical else ax.set_xlim)(lim)

    def build(self, scenario):
        """The simulation data and the law, handed the reference designed for it
        (:func:`~gnc_jax.systems.capsule.reference.law_reference`) as its ``ctx``."""
        config, sim = scenario.config, capsule_sim.build(scenario)
        law = self.laws()[config["guidance"]["law"]]
        return sim, self.build_law(config, law_reference(law, config, sim))

    def simulate(self, params, law, key, record=False):
        return capsule_sim.simulate(params, law, key, record=record)

    def smooth_objective(self, outcomes):
        """Mean squared chute-deploy error (km^2)."""
        return jnp.mean(outcomes.downrange_err_km**2 + outcomes.crossrange_err_km**2)

    def statistics(self, outcomes, ok):
        return _capsule_statistics(outcomes, ok)

    def figure_traces(self, summary, runs, scenario):
        ok = runs["status"] == Status.ok
        return {"ok_runs": TraceRequest(tuple(np.flatnonzero(ok).tolist()), every=5)}

    def figures(self, summary, runs, scenario, out, traces=None):
        return capsule_figures(summary, runs, scenario, out, traces)
