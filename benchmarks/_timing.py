"""Timing helper shared by the benchmark scripts (run them as ``python benchmarks/<name>.py``)."""

import time

import jax


def best_of(fn, repeats):
    """Smallest wall time (s) of ``repeats`` calls of ``fn``, each waited for with
    ``block_until_ready``."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return min(times)
