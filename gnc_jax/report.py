"""PNG reports of a study directory written by ``gnc-jax run`` (``gnc-jax report DIR``).

The figures are the study's system's (:meth:`gnc_jax.systems.AbstractSystem.figures`).
"""

import pathlib

from .results import load_results


def report(run_dir, out_dir=None) -> list[str]:
    """Write the PNG figures of a study directory; returns their paths.

    Args:
        run_dir: a directory written by ``gnc-jax run`` / :meth:`Study.save`.
        out_dir: where to write the PNGs (default: ``run_dir``).
    """
    summary, runs, scenario = load_results(run_dir)
    out = pathlib.Path(out_dir or run_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [str(p) for p in scenario.system.figures(summary, runs, scenario, out)]
