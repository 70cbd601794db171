"""The capsule system's contract: lunar-return skip entry (seed 003).

Truth, actuator and sensors are in :mod:`gnc_jax.systems.capsule.simulation`; the law in
:mod:`gnc_jax.guidance.entry.skip_entry`, with the second-entry reference the system designs
for it in :mod:`gnc_jax.systems.capsule.reference`; the scenario parameters in
:mod:`gnc_jax.systems.capsule.params` (their cross-field checks in
:mod:`gnc_jax.systems.capsule.schema`); the report figures in
:mod:`gnc_jax.systems.capsule.figures`; the envelope pre-check in
:mod:`gnc_jax.systems.capsule.envelope`.
"""

import math
from typing import Any, ClassVar

import jax.numpy as jnp
import numpy as np

from ..._status import Status
from ...guidance.entry.base import AbstractEntryGuidance
from ...params import from_scenario
from ...statistics import spread, std
from ..base import (
    CPU_SOURCE,
    H100_SOURCE,
    AbstractSystem,
    StepCost,
    TraceRequest,
    register_system,
)
from . import simulation as capsule_sim
from .envelope import check_cells, draw_overlay, require_within_load_limit
from .figures import capsule_figures
from .params import PARAMETER_MODULES, Entry, GuidanceParams, SimulationParams, loop_counts
from .reference import law_mission
from .schema import check as check_config
from .sources import BUDGET_METRICS, ERROR_SOURCES, SOURCE_GROUPS

# Cost model of CapsuleSystem.steps_per_run: trajectory fractions of the paper scenario (the
# law's predictions per corrector cycle: its family's prediction_steps).
MEAN_SPEED_FRACTION = 0.58  # chute range / (flight time x entry speed): 8000 km in 1250 s at 11
FIRST_ENTRY_FRACTION = 0.16  # corrector-active first entry over the flight: (229 - 34) / 1250 s


def _interval(x: np.ndarray) -> dict[str, Any]:
    """Mean, spread and range of ``x``; the spread and the 3σ interval ``None`` from one run."""
    m, s = float(np.mean(x)), std(x)
    return dict(
        mean=m,
        std=s,
        min=float(np.min(x)),
        max=float(np.max(x)),
        three_sigma=None if s is None else [m - 3 * s, m + 3 * s],
    )


def _text(interval) -> str | None:
    return None if interval is None else "{:.2f} .. {:.2f}".format(*interval)


def _capsule_statistics(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    if not ok.any():
        return {}
    out: dict[str, Any] = {
        "downrange_err_km": _interval(o["downrange_err_km"][ok]),
        "crossrange_err_km": _interval(o["crossrange_err_km"][ok]),
        "downrange_err_km_3sigma": _text(_interval(o["downrange_err_km"][ok])["three_sigma"]),
        "crossrange_err_km_3sigma": _text(_interval(o["crossrange_err_km"][ok])["three_sigma"]),
        # the empirical interval holding 99.73 % of the runs (what mean +- 3 std means for a
        # Gaussian), which a few heavy-tailed runs do not stretch
        **{
            f"{name}_central_99_73": _text(
                spread(lambda x: np.percentile(x, [0.135, 99.865]), o[name][ok])
            )
            for name in ("downrange_err_km", "crossrange_err_km")
        },
        **{
            f"{name}_outside_2p5_km": int(np.sum(np.abs(o[name][ok]) > 2.5))
            for name in ("downrange_err_km", "crossrange_err_km")
        },
        # the chute-deploy 3-sigma error: the larger end of the downrange and crossrange
        # mean +- 3 std intervals (what "within +-5 km" bounds)
        "chute_3sigma_km": spread(
            lambda _: max(
                abs(x)
                for name in ("downrange_err_km", "crossrange_err_km")
                for x in _interval(o[name][ok])["three_sigma"]
            ),
            o["downrange_err_km"][ok],
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


@register_system
class CapsuleSystem(AbstractSystem):
    name = "capsule"
    error_sources = ERROR_SOURCES
    source_groups = SOURCE_GROUPS
    budget_metrics = BUDGET_METRICS
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

    # measured with benchmarks/capsule.py (per-run time against the chunk size): the lowest
    # per-run time is at 256 runs per device, whose working set (about 2 kB per run of
    # live buffers, the compiled chunk's temp memory) half fills a 1 MB L2 cache
    chunk_per_device = 256
    # GPU: lunar-skip-entry on one H100 (a guidance cycle unrolled whole, the corrector's
    # predictor steps masked) took 0.51 s for 512 runs and 1.34 s for 100,000 (one chunk
    # each): 76 us per sequential step plus 1.25 ns per run-step.
    # CPU: lunar-skip-entry on the 2-core development machine (2 host devices), one chunk
    # each: 16 runs 0.218 s, 512 runs 1.56 s (benchmarks/cost_calibration.py --fit): 0.81 us
    # per run-step on a device plus 26 us per sequential step (a small batch still pays for
    # the corrector rounds of its slowest run).
    step_costs: ClassVar[dict[str, StepCost]] = {
        "gpu": StepCost(1.25e-9, 7.6e-5, "lunar-skip-entry on " + H100_SOURCE),
        "cpu": StepCost(8.1e-7, 2.6e-5, "lunar-skip-entry on " + CPU_SOURCE),
    }
    run_bytes: ClassVar[int] = 2_500  # the compiled batch's bytes per run on the CPU (2,476)

    def check(self, config):
        check_config(config)
        law = self.laws()[config["guidance"]["law"]]
        altitude_m = float(from_scenario(Entry, config).altitude_m)
        law.check_entry(config["guidance"][law.law_name], altitude_m)

    def steps_per_run(self, config):
        """Truth RK4 steps plus the predictor's RK4 steps (one truth-step equivalent each:
        both are an RK4 step of an entry vector field), estimated from the scenario alone.

        The truth loop runs until the flight is down (about ``range / (MEAN_SPEED_FRACTION
        * entry speed)``, at most ``max_time_s``) in steps of ``dt_s``. Each corrector cycle
        of the first entry (about ``FIRST_ENTRY_FRACTION`` of the flight) costs the law's
        :meth:`~gnc_jax.guidance.entry.base.AbstractEntryGuidance.prediction_steps`. The
        fractions are those of the paper scenario (256 runs: flight 1250 s, guidance
        34-229 s); the estimate is within 0.6-1.6x of the measured time on the cases of
        ``benchmarks/capsule_cost.py``.
        """
        e = from_scenario(Entry, config)
        s = from_scenario(SimulationParams, config)
        clock = loop_counts(s, from_scenario(GuidanceParams, config))
        flight_s = min(s.max_time_s, e.range_m / (MEAN_SPEED_FRACTION * float(e.speed_mps)))
        truth = math.ceil(flight_s / clock.dt_s)
        law = self.laws()[config["guidance"]["law"]]
        per_cycle = law.prediction_steps(config["guidance"][law.law_name], flight_s)
        if per_cycle is None:
            return float(truth)
        cycles = FIRST_ENTRY_FRACTION * flight_s / clock.pc_period_s
        return float(truth + cycles * per_cycle)

    def envelope_check(self, configs, runs=None, seed=None, **options):
        """The entry corridor and footprint pre-check of
        :func:`~gnc_jax.systems.capsule.envelope.check_cells`."""
        return check_cells(configs, runs, seed)

    def envelope_overlay(self, ax, envelope, x_key, y_key):
        """The corridor and footprints of
        :func:`~gnc_jax.systems.capsule.envelope.draw_overlay`."""
        draw_overlay(ax, envelope, x_key, y_key)

    def build(self, scenario):
        """The simulation data and the law, handed the mission and the reference designed for
        it (:func:`~gnc_jax.systems.capsule.reference.law_mission`) as its ``ctx``; an entry
        too steep for the load limit is refused first
        (:func:`~gnc_jax.systems.capsule.envelope.require_within_load_limit`)."""
        require_within_load_limit(scenario.config)
        config, sim = scenario.config, capsule_sim.build(scenario)
        law = self.laws()[config["guidance"]["law"]]
        return sim, self.build_law(config, law_mission(law, config, sim))

    reverse_on_one_device: ClassVar[bool] = True  # the flight's checkpointed while_loop
    # forward mode 4.3x a plain run for one parameter, 10.7x for the four gains; the tuner's
    # reverse mode 3.2-3.4x whatever their number (256 runs, one device, idle:
    # benchmarks/tune_gradient.py --only capsule --modes value,forward,reverse)
    gradient_costs: ClassVar[tuple[float, float, float]] = (2.2, 2.1, 3.4)

    def reverse_mode(self, params, differentiated=None):
        """The flight's checkpointed loops (:func:`~.simulation.reverse_mode`), the
        corrector's solutions passing no derivative when every ``differentiated`` name is a
        field of the law's ``acts_after_corrector`` (its tracking gains and their schedules)."""
        return capsule_sim.reverse_mode(params, not self._after_corrector(differentiated))

    def _after_corrector(self, names) -> bool:
        if not names:
            return False
        laws = self.laws()
        for name in names:
            section, law_name, field = (name.split("[")[0].split(".", 2) + ["", ""])[:3]
            law = laws.get(law_name) if section == "guidance" else None
            if law is None or field not in getattr(law, "acts_after_corrector", ()):
                return False
        return True

    def simulate(self, params, law, key, record=False):
        return capsule_sim.simulate(params, law, key, record=record)

    def smooth_objective(self, outcomes):
        """Mean squared chute-deploy error (km^2)."""
        return jnp.mean(outcomes.downrange_err_km**2 + outcomes.crossrange_err_km**2)

    def statistics(self, outcomes, ok):
        return _capsule_statistics(outcomes, ok)

    def figure_traces(self, summary, runs, scenario):
        ok = np.flatnonzero(runs["status"] == Status.ok)
        # no ok run: nothing to fly again (the trace figures are left out)
        return {"ok_runs": TraceRequest(tuple(ok.tolist()), every=5)} if len(ok) else {}

    def figures(self, summary, runs, scenario, out, traces=None):
        return capsule_figures(summary, runs, scenario, out, traces)
