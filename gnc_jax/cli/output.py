"""What the commands print: a study's summary and a scenario's warnings."""

import sys


def _too_many_failed(summary: dict, max_failed: float) -> bool:
    return summary["failed"] > max_failed * summary["runs"]


def _print_summary(summary: dict) -> None:
    skip = {"paper", "firings_histogram", "failed_by_status", "description", "warnings"}
    width = max(len(k) for k in summary)
    for key, value in summary.items():
        if key in skip:
            continue
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        if value is None:  # a spread from fewer than two ok runs
            text = "n/a"
        if isinstance(value, list) and value and all(isinstance(v, float) for v in value):
            text = "[" + ", ".join(f"{v:.4g}" for v in value) + "]"
        print(f"  {key:<{width}}  {text}")
    if summary.get("failed_by_status"):
        print(f"  {'failed_by_status':<{width}}  {summary['failed_by_status']}")
    if summary.get("firings_histogram"):
        print(f"  {'firings_histogram':<{width}}  {summary['firings_histogram']}")
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
