"""The linear method: each metric's response to each factor's draws, linearised about the
nominal run by forward-mode autodiff.

A factor's draws enter a run as ``scale_f * w`` (:class:`~gnc_jax._random.DrawKey`). At
``scale = 0`` every draw is zero (the nominal run, the models the filter and the law hold
unchanged) and ``d metric / d scale_f = J_f w_f``: the first-order response to the run's own
draws of factor ``f``. Over the runs, ``mean((J_f w_f)^2) = sum_j J_fj^2`` is the variance the
linearisation predicts for ``f`` (LinCov's answer), whose share of the Monte Carlo variance
the budget reports beside the pick-freeze and one-at-a-time shares. Where the loop's logic
switches (an engine on/off trigger, a phase change), the nominal run's derivative does not
see what the dispersed runs do, and the shares disagree.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._random import DrawKey, run_key
from .._status import Status


@functools.lru_cache(maxsize=8)
def _linearised(system, metric_names: tuple, n_scale: int, lay: tuple):
    metrics = [system.budget_metrics[m] for m in metric_names]

    def one(sim, law, seed, i):
        key = run_key(seed, i)

        def f(scale):
            out = system.simulate(sim, law, DrawKey(key, key, jnp.zeros(n_scale, bool), scale, lay))
            o = out[0]._asdict()
            return jnp.stack([1.0 * m(o) for m in metrics]), o["status"]

        jac, status = jax.jacfwd(f, has_aux=True)(jnp.zeros(n_scale))
        return jac, status

    return jax.jit(jax.vmap(one, in_axes=(None, None, None, 0)))


def linear_responses(
    system,
    sim,
    law,
    seed: int,
    runs: int,
    metric_names,
    n_factors,
    lay,
    chunk: int = 64,
    progress=None,
):
    """``(J w, status)``: per metric, factor and run the linearised response (metric x factor
    x run) and the nominal run's status per run (the same for every run)."""
    fn = _linearised(system, tuple(metric_names), n_factors + 1, lay)
    seed_arr = jnp.asarray(seed, jnp.uint32)
    chunk = min(chunk, runs)
    parts, status = [], []
    for start in range(0, runs, chunk):
        idx = jnp.arange(start, start + chunk)
        jac, st = fn(sim, law, seed_arr, idx)
        parts.append(np.asarray(jac)[: runs - start, :, :n_factors])
        status.append(np.asarray(st)[: runs - start])
        if progress is not None:
            progress(min(chunk, runs - start))
    jw = np.concatenate(parts).transpose(1, 2, 0)
    return jw, np.concatenate(status) == Status.ok


__all__ = ["linear_responses"]
