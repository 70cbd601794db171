"""Several studies of one system in one compiled call: the cells of an envelope, or any list of
scenarios that differ only in the values of their parameters.

Gains and scenario values are arguments of a system's compiled program, not constants, so
cells whose built parameters have the same structure (tree, static fields, shapes and dtypes)
share one program. :func:`run_cells` stacks their parameters along a leading cell axis and runs
``vmap`` over cells of ``vmap`` over runs: on a GPU, where a closed loop costs its sequential
steps' latency whatever the batch, a grid of small studies then costs about one study instead
of one per cell. Cells of another structure (another law, another entry mode) form their own
group and program.

Run ``i`` of every cell uses the key of run ``i`` of a study with the same seed, so a cell's
outcomes are those of :func:`gnc_jax.run_study` of its scenario: statuses and integer outcomes
equal, floats within the system's ``batch_tolerance`` (another program, which may round
differently).
"""

import time

import jax
import jax.numpy as jnp
import numpy as np

from ._numerics import layout_for, using_loop_shape
from ._random import plan_key
from .backend import describe, placement, select
from .montecarlo import MAX_HOURS, MAX_MEMORY_FRACTION, _check_memory, build, structure
from .planner import estimate_cost, plan_chunk
from .scenario import Scenario, ScenarioError
from .study import Study, _checked_cost, _nan_to_status
from .systems.base import get_system


def _program(system):
    def cells(sims, laws, seed, indices):
        def one(sim, law):
            return jax.vmap(lambda i: system.simulate(sim, law, plan_key(seed, i))[0])(indices)

        return jax.vmap(one)(sims, laws)

    return jax.jit(cells)


def run_cells(
    scenarios: list[Scenario],
    runs: int,
    seed: int,
    device: str | None = None,
    max_hours: float = MAX_HOURS,
    max_memory_fraction: float = MAX_MEMORY_FRACTION,
    chunk_size: int | None = None,
) -> list:
    """One :class:`~gnc_jax.study.Study` per scenario (all of one system), the cells of equal
    structure run as one batch on one device of ``device`` (``"cpu"``, ``"gpu"``, ``"auto"``).

    A cell that :func:`~gnc_jax.run_study` would refuse (a cost over ``max_hours``, a reference
    design that does not converge) gets its :class:`~gnc_jax.scenario.ScenarioError` in its
    place in the returned list. A cell's
    ``compile_s`` is its group's compile time for the group's first cell, 0 for the others;
    its ``wall_s`` is its share (1 / cells) of the group's wall time. Runs are split in chunks
    of ``chunk_size`` runs per cell, by default the planner's chunk for the whole batch (cells
    x runs) shared out, halved while a compiled batch does not fit ``max_memory_fraction`` of
    the device's memory.
    """
    if isinstance(runs, bool) or not isinstance(runs, int) or runs <= 0:
        raise ScenarioError(f"runs: {runs!r}; allowed: an integer >= 1")
    if chunk_size is not None and (
        isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size <= 0
    ):
        raise ScenarioError(f"chunk_size: {chunk_size!r}; allowed: an integer >= 1")
    if not scenarios:
        return []
    kinds = {s.kind for s in scenarios}
    if len(kinds) > 1:
        raise ScenarioError(f"scenarios: systems {sorted(kinds)}; allowed: one system")
    system = get_system(scenarios[0].kind)
    backend = select(device)
    results: list = [None] * len(scenarios)
    groups: dict = {}
    with placement(backend):
        for n, scenario in enumerate(scenarios):
            try:
                _checked_cost(scenario, runs, 1, max_hours, backend)
                built = build(scenario)
            except ScenarioError as e:
                results[n] = e
                continue
            groups.setdefault(structure(built), []).append((n, built))
        shape = layout_for(backend.platform, system)
        for members in groups.values():
            outs, compile_s, wall_s, chunk = _run_group(
                system, scenarios[members[0][0]], [b for _, b in members], runs, seed, backend,
                shape, max_memory_fraction, chunk_size,
            )  # fmt: skip
            for k, (n, _) in enumerate(members):
                outcomes = {f: np.asarray(v[k]) for f, v in outs.items()}
                _nan_to_status(outcomes)
                results[n] = Study(
                    scenarios[n], runs, seed, outcomes, compile_s if k == 0 else 0.0,
                    wall_s / len(members), 1, chunk, device=describe(backend, 1),
                )  # fmt: skip
    return results


def _run_group(system, scenario, built, runs, seed, backend, shape, fraction, chunk_size):
    """The outcomes ``{field: (cells, runs)}`` of one group, its compile and wall time and the
    chunk of runs per call."""
    cells = len(built)
    sims, laws = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *built)
    seed_arr = jnp.asarray(seed, dtype=jnp.uint32)
    cost = estimate_cost(scenario, cells * runs, 1, backend)
    planned = plan_chunk(system, cells * runs, None, backend, 1, cost, False, False) // cells
    chunk = min(chunk_size or max(1, planned), runs)
    fn = _program(system)
    t0 = time.perf_counter()
    while True:
        with using_loop_shape(shape):
            compiled = fn.lower(sims, laws, seed_arr, jnp.arange(chunk)).compile()
        refusal = _check_memory(compiled, cells * chunk, backend, fraction)
        if refusal is None:
            break
        if chunk == 1:
            raise refusal
        chunk = -(-chunk // 2)
    compile_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    parts = []
    for start in range(0, runs, chunk):
        idx = np.minimum(np.arange(start, start + chunk), runs - 1)  # the last one padded
        out = compiled(sims, laws, seed_arr, jnp.asarray(idx))
        keep = min(chunk, runs - start)
        parts.append({f: np.asarray(v)[:, :keep] for f, v in out._asdict().items()})
    wall_s = time.perf_counter() - t1
    outs = {f: np.concatenate([p[f] for p in parts], axis=1) for f in parts[0]}
    return outs, compile_s, wall_s, chunk
