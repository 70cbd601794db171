"""What the commands print: a study's summary and a scenario's warnings."""

import sys


def _too_many_failed(summary: dict, max_failed: float) -> bool:
    return summary["failed"] > max_failed * summary["runs"]


def _format_value(value) -> str:
    """One summary value as text: floats to 4 significant digits, `None` (a spread from fewer
    than two ok runs) as n/a, intervals as [lo, hi], a record as `key value` pairs."""
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_format_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_format_value(v)}" for k, v in value.items())
    return str(value)


def _print_summary(summary: dict) -> None:
    skip = {"paper", "firings_histogram", "failed_by_status", "description", "warnings"}
    width = max(len(k) for k in summary)
    for key, value in summary.items():
        if key in skip:
            continue
        print(f"  {key:<{width}}  {_format_value(value)}")
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
        for metric, paper, ours in rows:
            print(f"    {metric:<16} {paper:>10} {ours:>10}")


def _print_warnings(scenario) -> None:
    """The scenario's warnings (valid but doubtful settings), one line each, on stderr."""
    from ..systems import get_system

    for line in get_system(scenario.kind).warnings(scenario.config):
        print(f"gnc-jax: warning: {line}", file=sys.stderr)
