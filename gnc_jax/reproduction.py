"""``gnc-jax reproduce``: every packaged paper scenario, paper and gnc_jax side by side."""

import json
import pathlib

from .scenario import ScenarioError, list_scenarios
from .study import run_study
from .systems.base import get_system


def comparison_rows(summary: dict) -> list[tuple[str, str, str]]:
    """``(metric, paper, gnc_jax)`` rows for every published metric of a summary: "—" where
    the summary has no such key (no ok run), "n/a" where it holds ``None`` (a statistic its ok
    runs do not give, such as a spread from one run)."""
    rows = []
    try:
        labels = get_system(summary.get("kind", "")).paper_labels
    except ScenarioError:
        labels = {}
    for key, paper in summary.get("paper", {}).items():
        ours = summary.get(key)
        fmt = lambda v: f"{v:.4g}" if isinstance(v, float) else str(v)
        shown = fmt(ours) if ours is not None else ("n/a" if key in summary else "—")
        rows.append((labels.get(key, key), fmt(paper), shown))
    return rows


def markdown_table(summaries: list[dict]) -> str:
    lines = ["| scenario | runs | metric | paper | gnc_jax |", "|---|---|---|---|---|"]
    for s in summaries:
        for i, (metric, paper, ours) in enumerate(comparison_rows(s)):
            name = f"`{s['scenario']}`" if i == 0 else ""
            runs = str(s["runs"]) if i == 0 else ""
            lines.append(f"| {name} | {runs} | {metric} | {paper} | {ours} |")
    return "\n".join(lines)


def reproduce(
    out_dir, runs: int | None = None, only=None, progress=None, echo=print, max_hours=None
) -> list:
    """Run every packaged scenario at its paper run count (or ``runs``), save and compare.

    Writes ``out_dir/<scenario>/`` (summary.json, runs/, scenario.toml) and
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
        limits = {} if max_hours is None else {"max_hours": max_hours}
        study = run_study(scenario, runs=n, progress=progress, **limits)
        study.save(out / scenario.name, overwrite=True)
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
