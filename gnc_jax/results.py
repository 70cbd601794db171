"""Study results: summary statistics, ``summary.json``, ``runs.parquet`` and the resolved TOML.

Only runs whose status is ``ok`` enter the statistics; the others are counted in ``failed``
(with a count per status) and flagged in ``runs.parquet``.
"""

import json
import os
import pathlib
import platform
from typing import Any

import numpy as np

from ._status import Status


def _machine_note(study) -> str:
    import jax

    return (
        f"{platform.machine()} {os.cpu_count()} cores, {study.n_devices} XLA host devices, "
        f"jax {jax.__version__}, {platform.python_implementation()} "
        f"{platform.python_version()}"
    )


def _impactor_stats(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    miss = o["miss_m"][ok]
    dv = o["dv_mps"][ok]
    firings = o["firings"][ok]
    if miss.size == 0:
        return {}
    counts = np.bincount(firings)
    return dict(
        miss_rms_m=float(np.sqrt(np.mean(miss**2))),
        miss_mean_m=float(np.mean(miss)),
        miss_max_m=float(np.max(miss)),
        miss_p99_m=float(np.percentile(miss, 99)),
        miss_t_mean_m=float(np.mean(o["miss_t_m"][ok])),
        miss_r_mean_m=float(np.mean(o["miss_r_m"][ok])),
        dv_mean_mps=float(np.mean(dv)),
        dv_std_mps=float(np.std(dv)),
        dv_max_mps=float(np.max(dv)),
        firings_mean=float(np.mean(firings)),
        firings_max=int(np.max(firings)),
        firings_mode=int(np.argmax(counts)),
        firings_histogram={int(k): int(v) for k, v in enumerate(counts) if v},
        fuel_mean_kg=float(np.mean(o["fuel_kg"][ok])),
    )


def _impactor_kind_stats(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    """The impactor statistics plus those of the seed 000/002 navigation front ends."""
    out = _impactor_stats(o, ok)
    if out:
        out.update(
            los_error_rms_urad_mean=float(np.mean(o["los_error_rms_urad"][ok])),
            images_rejected_max=int(np.max(o["images_rejected"][ok])),
            images_rejected_mean=float(np.mean(o["images_rejected"][ok])),
        )
    return out


def _interval(x: np.ndarray) -> dict[str, Any]:
    m, s = float(np.mean(x)), float(np.std(x))
    return dict(
        mean=m,
        std=s,
        min=float(np.min(x)),
        max=float(np.max(x)),
        three_sigma=[m - 3 * s, m + 3 * s],
    )


def _capsule_stats(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
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


def _midcourse_stats(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
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
        b_err_r_km_std=float(np.std(o["b_err_r_m"][ok] / 1e3)),
        b_err_t_km_std=float(np.std(o["b_err_t_m"][ok] / 1e3)),
        tof_err_s_std=float(np.std(o["tof_err_s"][ok])),
        b0_err_km_rms=rms(b0),
        b0_err_km_max=float(np.max(b0)),
        b0_err_r_km_std=float(np.std(o["b0_err_r_m"][ok] / 1e3)),
        b0_err_t_km_std=float(np.std(o["b0_err_t_m"][ok] / 1e3)),
        tof0_err_s_rms=rms(tof0),
        dv_max_mps=float(np.max(dv)),
        dv_first_mean_mps=float(np.mean(o["dv_first_mps"][ok])),
        dv_ref_mean_mps=float(np.mean(o["dv_ref_mps"][ok])),
        dv_increase_pct_mean=float(np.mean(o["dv_increase_pct"][ok])),
        later_dv_max_mps=float(np.max(later)) if later.size else 0.0,
        later_dv_below_0p2_pct=float(100.0 * np.mean(later < 0.2)) if later.size else 0.0,
        corrections_max=int(np.max(count)),
        correction_every_fix_pct=float(100.0 * np.mean(count == per_fix.shape[1])),
        iterations_mean=float(np.mean(o["iterations"][ok][count > 0])) if np.any(count) else 0.0,
        ground_calls_total=int(np.sum(o["ground_calls"][ok])),
    )


STATS = {"impactor": _impactor_kind_stats, "capsule": _capsule_stats, "midcourse": _midcourse_stats}


def _pn_stats(o: dict[str, np.ndarray], ok: np.ndarray) -> dict[str, Any]:
    """Seed 004: miss (B-plane), total Δv, firings (pulse trains), as the impactor plus extras."""
    if not ok.any():
        return {}
    out = _impactor_stats(o, ok)
    miss = o["miss_m"][ok]
    out.update(
        miss_std_m=float(np.std(miss)),
        miss_t_std_m=float(np.std(o["miss_t_m"][ok])),
        miss_r_std_m=float(np.std(o["miss_r_m"][ok])),
        dv_min_mps=float(np.min(o["dv_mps"][ok])),
        ignitions_mean=float(np.mean(o["ignitions"][ok])),
        pulses_mean=float(np.mean(o["pulses"][ok])),
        last_firing_s_mean=float(np.mean(o["last_firing_s"][ok])),
        nav_position_error_m_rms=float(np.sqrt(np.mean(o["nav_position_error_m"][ok] ** 2))),
    )
    return out


STATS["pn"] = _pn_stats


def summarize(study) -> dict[str, Any]:
    """The ``summary.json`` content of a study."""
    status = study.outcomes["status"]
    ok = status == Status.ok
    failed = {Status(int(s)).name: int(np.sum(status == s)) for s in np.unique(status) if s != 0}
    sc = study.scenario
    out: dict[str, Any] = dict(
        scenario=sc.name,
        kind=sc.kind,
        description=sc.description,
        runs=study.runs,
        failed=int(np.sum(~ok)),
        failed_by_status=failed,
        seed=study.seed,
        wall_s=round(study.wall_s, 4),
        compile_s=round(study.compile_s, 4),
        runs_per_s=round(study.runs / study.wall_s, 2) if study.wall_s > 0 else None,
        chunk_size=study.chunk_size,
        machine=_machine_note(study),
    )
    if sc.kind == "impactor":
        out["law"] = sc.config["guidance"]["law"]
    out.update(STATS[sc.kind](study.outcomes, ok))
    out["paper"] = dict(sc.paper)
    return out


def runs_table(study):
    """One row per run: index, status, outcomes and dispersion draws (vectors split in columns)."""
    import pyarrow as pa

    cols: dict[str, Any] = {"run": np.arange(study.runs)}
    status = study.outcomes["status"]
    cols["status"] = status
    cols["status_name"] = [Status(int(s)).name for s in status]
    for name, arr in study.outcomes.items():
        if name == "status":
            continue
        if arr.ndim == 1:
            cols[name] = arr
        else:
            flat = arr.reshape(arr.shape[0], -1)
            for j in range(flat.shape[1]):
                cols[f"{name}_{j}"] = flat[:, j]
    return pa.table(cols)


def save_study(study, out_dir) -> dict[str, str]:
    """Write ``summary.json``, ``runs.parquet`` and ``scenario.toml`` into ``out_dir``."""
    import pyarrow.parquet as pq

    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "summary": out / "summary.json",
        "runs": out / "runs.parquet",
        "scenario": out / "scenario.toml",
    }
    paths["summary"].write_text(json.dumps(study.summary(), indent=2) + "\n")
    pq.write_table(runs_table(study), paths["runs"])
    paths["scenario"].write_text(study.scenario.to_toml())
    return {k: str(v) for k, v in paths.items()}


def load_results(out_dir) -> tuple[dict, "Any", "Any"]:
    """Read back ``(summary, runs table as a dict of numpy arrays, scenario)`` from a run dir."""
    import pyarrow.parquet as pq

    from .scenario import load_scenario

    out = pathlib.Path(out_dir)
    for name in ("summary.json", "runs.parquet", "scenario.toml"):
        if not (out / name).is_file():
            raise FileNotFoundError(f"{out / name}: missing; run `gnc-jax run ... --out {out}`")
    summary = json.loads((out / "summary.json").read_text())
    table = pq.read_table(out / "runs.parquet")
    runs = {c: table.column(c).to_numpy(zero_copy_only=False) for c in table.column_names}
    scenario = load_scenario(out / "scenario.toml")
    return summary, runs, scenario
