"""Binomial intervals against scipy (an established implementation)."""

import re

import numpy as np
import pytest
from scipy import stats

from gnc_jax.statistics import wilson_interval


@pytest.mark.parametrize("n", [1, 7, 40, 300, 2000])
def test_wilson_interval_matches_scipy(n):
    for k in sorted({0, 1, n // 3, n // 2, n - 1, n}):
        ref = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
        np.testing.assert_allclose(wilson_interval(k, n), (ref.low, ref.high), atol=1e-12)


def test_wilson_interval_covers_at_its_level():
    """Coverage by brute force: over many binomial samples at p = 0.3, n = 200, the 95 %
    interval holds p in 95 +- 1.5 % of them (Wilson's coverage is close to nominal there)."""
    rng = np.random.default_rng(0)
    n, p = 200, 0.3
    ks = rng.binomial(n, p, size=4000)
    cover = np.mean([lo <= p <= hi for lo, hi in (wilson_interval(int(k), n) for k in ks)])
    assert abs(cover - 0.95) < 0.015


def test_wilson_interval_refuses_bad_counts():
    with pytest.raises(ValueError, match="0 <= k <= n"):
        wilson_interval(5, 3)


def _outcomes(outcome_type, n, rng):
    """Every field of a system's outcome as ``n`` distinct values (a per-fix table for the
    midcourse Δv), integers where the statistics count."""
    o = {f: rng.uniform(0.5, 2.0, n) for f in outcome_type._fields}
    counts = "firings ignitions pulses predictions cycle_predictions_max pc_cycles"
    counts += " corrector_failures reversals corrections goal_met"
    for f in counts.split():
        o[f] = rng.integers(1, 4, n)
    o["status"] = np.zeros(n, dtype=np.int32)
    o["dv_per_fix_mps"] = rng.uniform(0.0, 1.0, (n, 3))
    return o


@pytest.mark.parametrize("kind", ["impactor", "intercept", "capsule", "midcourse"])
def test_a_spread_from_one_ok_run_is_none_not_zero(kind, capsys):
    """One ok run has no spread: every standard deviation and interval of the summary is None
    (null in summary.json) where 0 would read as a study without dispersion; the central
    values stay, and from two ok runs the spreads are numpy's."""
    from gnc_jax.cli.output import _print_summary
    from gnc_jax.reproduction import comparison_rows
    from gnc_jax.systems import get_system
    from gnc_jax.systems.capsule.state import CapsuleOutcome
    from gnc_jax.systems.impactor.state import ImpactorOutcome
    from gnc_jax.systems.intercept.state import PNOutcome
    from gnc_jax.systems.midcourse.simulation import MidcourseOutcome

    types = dict(impactor=ImpactorOutcome, intercept=PNOutcome, capsule=CapsuleOutcome,
                 midcourse=MidcourseOutcome)  # fmt: skip
    o = _outcomes(types[kind], 5, np.random.default_rng(1))
    system = get_system(kind)
    one = system.statistics(o, np.arange(5) == 2)
    two = system.statistics(o, np.arange(5) >= 3)
    spreads = [k for k in two if k.endswith(("_std", "_std_m", "_std_mps", "_3sigma"))]
    spreads += [k for k in two if "central" in k or k == "chute_3sigma_km"]
    assert spreads, kind
    for key in spreads:
        assert one[key] is None, key
        assert two[key] is not None, key
    std_keys = [k for k in spreads if "_std" in k and isinstance(two[k], float)]
    for key in std_keys:
        assert two[key] > 0.0, key
    for key in ("miss_rms_m", "dv_mean_mps", "load_peak_g_max", "b_err_km_rms"):
        if key in two:
            assert one[key] is not None and np.isfinite(one[key]), key
    if kind == "capsule":
        d = o["downrange_err_km"][3:]
        assert two["downrange_err_km"]["std"] == float(np.std(d))
    # the printed summary and the paper comparison say n/a where a spread is None
    paper = {key: "1.0 .. 2.0" if "3sigma" in key or "central" in key else 1.0 for key in spreads}
    _print_summary({"scenario": kind, "kind": kind, "runs": 5, "failed": 4, **one, "paper": paper})
    printed = capsys.readouterr().out
    assert "n/a" in printed and "paper vs gnc_jax" in printed
    shown = [ours for _, _, ours in comparison_rows({"kind": kind, **one, "paper": paper})]
    assert shown == ["n/a"] * len(spreads)
    # no ok run: no statistic at all, as a study without an ok run has always had
    assert system.statistics(o, np.zeros(5, bool)) == {}
    _print_summary({"scenario": kind, "runs": 5, "failed": 5})
    shown = [ours for _, _, ours in comparison_rows({"kind": kind, "paper": paper})]
    assert shown == ["—"] * len(spreads)


@pytest.mark.parametrize("kind", ["impactor", "intercept", "capsule", "midcourse"])
def test_the_printed_summary_shows_numbers_not_python_records(kind, capsys):
    """Every statistic of every system prints as numbers: records (the capsule's per-axis
    error records, the device) as `key value` pairs, intervals as [lo, hi], the firing
    histogram as runs per firing count, and a missing spread as n/a, never as a Python dict,
    `None` or a 17-digit float."""
    from gnc_jax.cli.output import _print_summary
    from gnc_jax.systems import get_system
    from gnc_jax.systems.capsule.state import CapsuleOutcome
    from gnc_jax.systems.impactor.state import ImpactorOutcome
    from gnc_jax.systems.intercept.state import PNOutcome
    from gnc_jax.systems.midcourse.simulation import MidcourseOutcome

    types = dict(impactor=ImpactorOutcome, intercept=PNOutcome, capsule=CapsuleOutcome,
                 midcourse=MidcourseOutcome)  # fmt: skip
    o = _outcomes(types[kind], 5, np.random.default_rng(2))
    system = get_system(kind)
    device = {"platform": "cpu", "device_count": 2, "memory_gb": 25.28123456}
    for ok in (np.arange(5) == 2, np.arange(5) >= 2):
        stats = system.statistics(o, ok)
        _print_summary({"scenario": kind, "runs": 5, "failed": 1, "device": device, **stats})
        printed = capsys.readouterr().out
        assert "{" not in printed and "None" not in printed and "': " not in printed, printed
        assert not re.search(r"\d\.\d{10,}", printed), printed
        assert "platform cpu, device_count 2, memory_gb 25.28" in printed


def test_interval_text_gives_the_width_three_significant_digits():
    """Both ends to the decimals of the width's third significant digit, the unit after."""
    from gnc_jax.statistics import interval_text

    assert interval_text([-0.8250488439999466, 0.21269251674699735], "km") == "[-0.83, 0.21] km"
    assert interval_text((7100.3, 7460.9), "m/s") == "[7100, 7461] m/s"
    assert interval_text((0.20654, 1.0)) == "[0.207, 1.000]"
    assert interval_text((0.0012344, 0.0015377), "m") == "[0.001234, 0.001538] m"
    assert interval_text((1.5, 1.5), "km") == "[1.5, 1.5] km"  # no width: 4 significant digits
    assert interval_text(None, "km") == "n/a"


def test_the_printed_intervals_carry_their_units(capsys):
    """Every interval of a printed capsule summary reads ``[lo, hi] unit`` whether the summary
    keeps it as numbers or as the paper's ``lo .. hi`` text: the 3σ ends are numpy's mean
    +- 3 std of the ok runs; the paper table's columns line up; the failed-runs line names
    the statuses without a Python dict."""
    from gnc_jax.cli.output import _failed_runs_line, _print_summary
    from gnc_jax.systems import get_system
    from gnc_jax.systems.capsule.state import CapsuleOutcome

    o = _outcomes(CapsuleOutcome, 5, np.random.default_rng(2))
    ok = np.arange(5) >= 2
    stats = get_system("capsule").statistics(o, ok)
    paper = {"downrange_err_km_3sigma": "-1.4 .. 1.7", "switch_speed_mps_mean": 7350.0}
    _print_summary({"scenario": "s", "kind": "capsule", "runs": 5, "failed": 2, **stats,
                    "paper": paper})  # fmt: skip
    lines = capsys.readouterr().out.splitlines()
    shown = {ln.split()[0]: ln.split(None, 1)[1] for ln in lines if ln.startswith("  ") and
             not ln.startswith("    ") and len(ln.split()) > 1}  # fmt: skip
    d, v = o["downrange_err_km"][ok], o["switch_speed_mps"][ok]
    lo, hi = d.mean() - 3 * np.std(d), d.mean() + 3 * np.std(d)
    assert shown["downrange_err_km_3sigma"] == f"[{lo:.2f}, {hi:.2f}] km"
    assert shown["downrange_err_km"].endswith(f"three_sigma [{lo:.2f}, {hi:.2f}] km")
    lo, hi = np.percentile(d, [0.135, 99.865])
    assert shown["downrange_err_km_central_99_73"] == f"[{lo:.2f}, {hi:.2f}] km"
    lo, hi = v.mean() - 3 * np.std(v), v.mean() + 3 * np.std(v)
    decimals = 2 - int(np.floor(np.log10(hi - lo)))
    assert shown["switch_speed_mps_3sigma"] == f"[{lo:.{decimals}f}, {hi:.{decimals}f}] m/s"
    table = lines[lines.index("  paper vs gnc_jax:") + 1 :]
    assert len(table) == 2 and len({len(row) for row in table}) == 1, table
    assert table[0].startswith("    downrange 3σ (km)  ") and "-1.4 .. 1.7" in table[0]
    failed = {"runs": 5, "failed": 3, "failed_by_status": {"nan": 2, "time_out": 1}}
    line = _failed_runs_line(failed, 0.1)
    assert line == "gnc-jax: 3 of 5 runs failed (nan 2, time_out 1), more than --max-failed 0.1"


def test_hit_probability_over_every_run_counts_failed_runs_where_they_crossed():
    """Over the ok runs as before; when runs failed, also over every run: a failed run inside
    the silhouette is a hit, one outside or with no crossing (NaN) a miss."""
    from gnc_jax.systems.impact import hit_statistics

    ratio = np.array([0.2, 0.9, 1.5, 0.5, 3.0, np.nan, 0.7])
    ok = np.array([True, True, True, False, False, False, True])
    s = hit_statistics({"silhouette_ratio": ratio}, ok)
    assert (s["hits"], s["hit_probability"]) == (3, 0.75)
    assert (s["hits_all_runs"], s["hit_probability_all_runs"]) == (4, 4 / 7)
    lo, hi = s["hit_probability_all_runs_ci95"]
    ref = stats.binomtest(4, 7).proportion_ci(0.95, method="wilson")
    assert (lo, hi) == pytest.approx((ref.low, ref.high), rel=1e-9)
    # every run ok: nothing more to say
    assert "hits_all_runs" not in hit_statistics({"silhouette_ratio": ratio[:3]}, ok[:3])
