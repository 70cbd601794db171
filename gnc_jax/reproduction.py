"""``gnc-jax reproduce``: every packaged paper scenario, paper and gnc_jax side by side."""

import json
import pathlib

from .montecarlo import run_study
from .scenario import list_scenarios

#: how each summary metric is printed
LABELS = {
    "miss_rms_m": "miss RMS (m)",
    "miss_max_m": "miss max (m)",
    "dv_mean_mps": "Δv mean (m/s)",
    "dv_max_mps": "Δv max (m/s)",
    "firings_max": "firings max",
    "firings_mode": "firings mode",
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
    "b_err_km_rms": "|ΔB| RMS (km)",
    "b_err_km_max": "|ΔB| max (km)",
    "tof_err_s_rms": "|Δt_TOF| RMS (s)",
    "tof_err_s_max": "|Δt_TOF| max (s)",
    "goal_met_pct": "goal met (% runs)",
    "corrections_mean": "corrections mean",
    "dv_increase_pct_mean": "Δv increase (%)",
    "dv_first_mean_mps": "first Δv (m/s)",
    "later_dv_below_0p2_pct": "later Δv < 0.2 m/s (%)",
    "correction_every_fix_pct": "burn every fix (% runs)",
    "iterations_mean": "Newton iterations mean",
    "b0_err_km_rms": "|ΔB| no guidance RMS (km)",
    "b0_err_r_km_std": "ΔB_R no guidance 1σ (km)",
    "b0_err_t_km_std": "ΔB_T no guidance 1σ (km)",
    "miss_mean_m": "miss mean (m)",
    "los_error_rms_urad_mean": "LOS meas. error RMS (µrad)",
}
LABELS.update({"firings_mean": "firings (mean)", "miss_mean_m": "miss mean (m)"})


def comparison_rows(summary: dict) -> list[tuple[str, str, str]]:
    """``(metric, paper, gnc_jax)`` rows for every published metric of a summary."""
    rows = []
    for key, paper in summary.get("paper", {}).items():
        ours = summary.get(key)
        fmt = lambda v: f"{v:.4g}" if isinstance(v, float) else str(v)
        rows.append((LABELS.get(key, key), fmt(paper), "—" if ours is None else fmt(ours)))
    return rows


def markdown_table(summaries: list[dict]) -> str:
    lines = ["| scenario | runs | metric | paper | gnc_jax |", "|---|---|---|---|---|"]
    for s in summaries:
        for i, (metric, paper, ours) in enumerate(comparison_rows(s)):
            name = f"`{s['scenario']}`" if i == 0 else ""
            runs = str(s["runs"]) if i == 0 else ""
            lines.append(f"| {name} | {runs} | {metric} | {paper} | {ours} |")
    return "\n".join(lines)


def reproduce(out_dir, runs: int | None = None, only=None, progress=None, echo=print) -> list:
    """Run every packaged scenario at its paper run count (or ``runs``), save and compare.

    Writes ``out_dir/<scenario>/`` (summary.json, runs.parquet, scenario.toml) and
    ``out_dir/reproduce.md`` / ``reproduce.json``. Returns the summaries.
    """
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summaries = []
    for scenario in list_scenarios():
        if only and scenario.name not in only:
            continue
        n = runs or scenario.runs
        echo(f"== {scenario.name}: {n} runs ({scenario.reference})")
        study = run_study(scenario, runs=n, progress=progress)
        study.save(out / scenario.name)
        s = study.summary()
        summaries.append(s)
        echo(f"   compile {s['compile_s']:.1f} s, study {s['wall_s']:.2f} s, failed {s['failed']}")
        width = max(len(m) for m, _, _ in comparison_rows(s)) if s.get("paper") else 10
        echo(f"   {'metric':<{width}}  {'paper':>10}  {'gnc_jax':>10}")
        for metric, paper, ours in comparison_rows(s):
            echo(f"   {metric:<{width}}  {paper:>10}  {ours:>10}")
    table = markdown_table(summaries)
    (out / "reproduce.md").write_text(
        "Produced by `gnc-jax reproduce --out " + str(out_dir) + "`\n\n" + table + "\n"
    )
    (out / "reproduce.json").write_text(json.dumps(summaries, indent=2) + "\n")
    return summaries
