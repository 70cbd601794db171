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


def warmed_best_of(fn, repeats):
    """:func:`best_of` after one warm-up call (compilation, caches)."""
    jax.block_until_ready(fn())
    return best_of(fn, repeats)


def python_loop_rate(system, sim, law, runs):
    """Baseline of the closed-loop benchmarks: a Python loop calling the jitted
    single-trajectory function run by run. Returns ``(compile_s, trajectories_per_s)``."""
    import gnc_jax as gj

    single = jax.jit(lambda s, l, k: system.simulate(s, l, k)[0])
    t0 = time.perf_counter()
    jax.block_until_ready(single(sim, law, gj.run_key(0, 0)))
    compile_s = time.perf_counter() - t0
    keys = [gj.run_key(0, i) for i in range(runs)]
    return compile_s, runs / best_of(lambda: [single(sim, law, k) for k in keys], 2)


def time_batch(system, sim, law, n, n_devices, repeats):
    """Compile the sharded, vmapped batch of runs 0..n-1 ahead of time, then time it.

    Returns ``(outcomes, compile_s, run_s)``."""
    import jax.numpy as jnp

    from gnc_jax.montecarlo import batch_function

    fn, _ = batch_function(system, n_devices)
    seed, idx = jnp.asarray(0, jnp.uint32), jnp.arange(n)
    t0 = time.perf_counter()
    compiled = fn.lower(sim, law, seed, idx).compile()
    compile_s = time.perf_counter() - t0
    out = jax.block_until_ready(compiled(sim, law, seed, idx))
    return out, compile_s, best_of(lambda: compiled(sim, law, seed, idx), repeats)
