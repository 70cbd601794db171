"""Exit codes of ``gnc-jax`` and the failed-run threshold of exit code 3."""

EXIT_REFUSED = 2  # bad input (or a runaway cost), refused before anything was compiled
EXIT_FAILED_RUNS = 3  # the study ran and its results were written, but too many runs failed
EXIT_INTERNAL = 4  # an unexpected error inside gnc_jax (a bug: please report it)
EXIT_ALL_FAILED = EXIT_FAILED_RUNS  # earlier name
MAX_FAILED = 0.01
"""Default of ``--max-failed``: the fraction of failed runs above which a study exits 3."""
DEBUG_ENV = "GNC_JAX_DEBUG"  # set to 1 to get the traceback of an internal error
