"""What the commands print: a study's summary and a scenario's warnings."""

import re
import sys

from ..statistics import interval_text


def _too_many_failed(summary: dict, max_failed: float) -> bool:
    return summary["failed"] > max_failed * summary["runs"]


_UNITS = {"km": "km", "m": "m", "mps": "m/s", "s": "s", "g": "g", "kg": "kg", "deg": "deg"}
"""Unit tokens of summary keys (``downrange_err_km_3sigma``, ``switch_speed_mps_3sigma``)."""
_INTERVAL_TEXT = re.compile(r"^(\S+) \.\. (\S+)$")
"""An interval that a summary keeps as text, ``"lo .. hi"`` (the paper's notation)."""


def _unit(key: str) -> str:
    """The unit a summary key names: its last unit token (``switch_speed_mps_3sigma``: m/s)."""
    return next((_UNITS[t] for t in reversed(key.split("_")) if t in _UNITS), "")


def _format_value(value, unit: str = "") -> str:
    """One summary value as text: floats to 4 significant digits, `None` (a spread from fewer
    than two ok runs) as n/a, an interval (a pair of numbers, or the ``"lo .. hi"`` text a
    summary keeps) as ``[lo, hi] unit``, a record as `key value` pairs."""
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, str) and (m := _INTERVAL_TEXT.match(value)):
        return f"[{m[1]}, {m[2]}]" + (f" {unit}" if unit else "")
    if isinstance(value, (list, tuple)):
        if len(value) == 2 and all(isinstance(v, (int, float)) for v in value):
            return interval_text(value, unit)
        return "[" + ", ".join(_format_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_format_value(v, unit)}" for k, v in value.items())
    return str(value)


def _failed_runs_line(summary: dict, max_failed: float) -> str:
    """The error line of a study with more failed runs than ``--max-failed`` allows."""
    return (
        f"gnc-jax: {summary['failed']} of {summary['runs']} runs failed "
        f"({_format_value(summary['failed_by_status'])}), more than --max-failed {max_failed:g}"
    )


def _print_summary(summary: dict) -> None:
    skip = {"paper", "firings_histogram", "failed_by_status", "description", "warnings"}
    width = max(len(k) for k in summary)
    for key, value in summary.items():
        if key in skip:
            continue
        print(f"  {key:<{width}}  {_format_value(value, _unit(key))}")
    if summary.get("failed_by_status"):
        print(f"  {'failed_by_status':<{width}}  {_format_value(summary['failed_by_status'])}")
    if summary.get("firings_histogram"):
        counts = {int(k): n for k, n in summary["firings_histogram"].items()}  # JSON: str keys
        runs = ", ".join(f"{k} firing{'s' * (k != 1)}: {n}" for k, n in counts.items())
        print(f"  {'firings_histogram':<{width}}  {runs}")
    from ..reproduction import comparison_rows

    rows = comparison_rows(summary)
    if rows:
        print("  paper vs gnc_jax:")
        wide = [max(10, *(len(row[i]) for row in rows)) for i in range(3)]
        for metric, paper, ours in rows:
            print(f"    {metric:<{wide[0]}}  {paper:>{wide[1]}}  {ours:>{wide[2]}}")


def _print_warnings(scenario) -> None:
    """The scenario's warnings (valid but doubtful settings), one line each, on stderr."""
    from ..systems import get_system

    for line in get_system(scenario.kind).warnings(scenario.config):
        print(f"gnc-jax: warning: {line}", file=sys.stderr)
