"""PNG reports of a study directory written by ``gnc-jax run`` (``gnc-jax report DIR``).

The figures are the study's system's (:meth:`gnc_jax.systems.AbstractSystem.figures`).
"""

import pathlib

from .results import ResultsError, load_results


def report(run_dir, out_dir=None) -> list[str]:
    """Write the PNG figures of a study directory; returns their paths.

    Args:
        run_dir: a directory written by ``gnc-jax run`` / :meth:`Study.save`.
        out_dir: where to write the PNGs (default: ``run_dir``).
    """
    summary, runs, scenario = load_results(run_dir)
    out = pathlib.Path(out_dir or run_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ResultsError(f"{out}: cannot create ({e.strerror or e})") from None
    try:
        return [str(p) for p in scenario.system.figures(summary, runs, scenario, out)]
    except KeyError as e:
        raise ResultsError(
            f"{pathlib.Path(run_dir)}: runs.parquet or summary.json lacks {e} (written by "
            "another gnc_jax version or edited?)"
        ) from None
    except PermissionError as e:
        raise ResultsError(f"{e.filename}: cannot write ({e.strerror})") from None
