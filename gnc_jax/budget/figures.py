"""The budget's figures (``gnc-jax report`` of a budget directory): per metric, bars per
source of its variance share by each method, with the bootstrap intervals."""

import json
import pathlib

import numpy as np

from ..plotting import pyplot, saver
from ..results import ResultsError
from .result import BUDGET_JSON, METHOD_LABELS


def budget_figures(run_dir, out_dir=None) -> list[pathlib.Path]:
    """``budget_<metric>.png`` for each metric of the budget in ``run_dir``."""
    try:
        budget = json.loads((pathlib.Path(run_dir) / BUDGET_JSON).read_text())
        rows, metrics, sources = budget["rows"], budget["metrics"], list(budget["factors"])
    except (OSError, ValueError, KeyError) as e:
        raise ResultsError(f"{run_dir}: not a budget directory ({e})") from None
    out = pathlib.Path(out_dir or run_dir)
    out.mkdir(parents=True, exist_ok=True)
    plt = pyplot()
    files: list = []
    save = saver(plt, out, files)
    methods = [m for m in METHOD_LABELS if any(r["method"] == m for r in rows)]
    width = 0.8 / max(len(methods), 1)
    x = np.arange(len(sources))
    for metric in metrics:
        fig, ax = plt.subplots(figsize=(max(6.0, 0.7 * len(sources) + 2), 4))
        for k, method in enumerate(methods):
            by = {r["source"]: r for r in rows if r["metric"] == metric and r["method"] == method}
            share = np.array([by[s]["share"] if s in by else np.nan for s in sources])
            lo = np.array([by[s]["share_lo"] if s in by else np.nan for s in sources])
            hi = np.array([by[s]["share_hi"] if s in by else np.nan for s in sources])
            err = np.abs(np.stack([share - lo, hi - share]))
            ax.bar(
                x + (k - (len(methods) - 1) / 2) * width,
                100 * share,
                width,
                yerr=100 * err,
                capsize=2,
                label=METHOD_LABELS[method],
            )
        c = budget["checks"].get(metric, {})
        title = f"{budget['scenario']}: {metric}"
        if "interaction" in c:
            title += f" (interactions {100 * c['interaction']:.0f} %)"
        ax.set_title(title)
        ax.set_ylabel("share of the variance (%)")
        ax.set_xticks(x, sources, rotation=30, ha="right")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.legend(fontsize=8)
        fig.tight_layout()
        save(fig, f"budget_{metric}.png")
    return files


__all__ = ["BUDGET_JSON", "budget_figures"]
