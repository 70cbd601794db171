"""The Monte Carlo engine: one ``vmap``ped single-trajectory simulator, sharded over host
devices, compiled ahead of time and run chunk by chunk (locally or on Dask workers); the cost
estimate and the memory guard; single runs and traces. :mod:`gnc_jax.study` builds studies on it.

Run ``i`` of a study with root seed ``s`` always uses the key
``jax.random.fold_in(jax.random.key(s), i)``, so a run's result never depends on the batch size,
the chunking or the number of devices. Batches are split over the host devices (one per core,
see ``gnc_jax._config``) with ``shard_map``; long studies run in chunks with a progress bar.
Compilation happens once, ahead of time, and is timed separately from the study.
"""

import dataclasses
import functools
import os
import time

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

from ._random import DrawPlan, plan_key, run_key
from .scenario import Scenario, ScenarioError
from .systems.base import AbstractSystem, get_system


def build(scenario: Scenario):
    """``(params, law)`` of a scenario, built by its system (SI units): what
    :func:`simulate_one` and :func:`run_study` run, for your own loops."""
    return get_system(scenario.kind).build(scenario)


def batch_function(system: AbstractSystem, n_devices: int | None = None):
    """``f(sim, law, seed, indices) -> outcomes`` vmapped over run indices, sharded over devices.

    ``seed``: the root seed, or a :class:`~gnc_jax._random.DrawPlan` that routes each error
    source's draws (the error budget).

    ``indices`` must have a length divisible by the number of devices.
    """
    devices = jax.devices()[: n_devices or len(jax.devices())]

    def per_device(sim, law, seed, indices):
        return jax.vmap(lambda i: system.simulate(sim, law, plan_key(seed, i))[0])(indices)

    if len(devices) == 1:
        return jax.jit(per_device), 1
    mesh = Mesh(np.array(devices), ("runs",))
    rep = PartitionSpec()
    sharded = jax.shard_map(
        per_device,
        mesh=mesh,
        in_specs=(rep, rep, rep, PartitionSpec("runs")),
        out_specs=PartitionSpec("runs"),
        check_vma=False,
    )
    return jax.jit(sharded), len(devices)


MAX_HOURS = 24.0
"""Default bound on a study's estimated wall time; above it :func:`run_study` refuses."""
MAX_MEMORY_FRACTION = 0.5
"""Default bound on a chunk's memory, as a fraction of the machine's physical memory."""
ANNOUNCE_S = 30.0
"""A study estimated to run longer than this announces its estimate and shows progress."""


@dataclasses.dataclass(frozen=True)
class CostEstimate:
    """What a study will cost, estimated from the scenario alone (before any compilation).

    Attributes:
        runs: runs in the study; steps_per_run: simulation steps of one run (the system's
        :meth:`~gnc_jax.systems.AbstractSystem.steps_per_run`; ``None`` when unknown);
        n_devices: host devices the runs are split over; seconds: estimated wall time after
        compilation, from the system's measured ``step_seconds`` (an estimate: within a
        factor of about 3 on the development machine).
    """

    runs: int
    steps_per_run: float | None
    n_devices: int
    seconds: float | None

    def __str__(self) -> str:
        if self.steps_per_run is None:
            return f"{self.runs} runs (no cost model for this system)"
        return (
            f"{self.runs} runs x {self.steps_per_run:.3g} steps = "
            f"{self.runs * self.steps_per_run:.3g} steps, about {_duration(self.seconds)} on "
            f"{self.n_devices} device{'s' if self.n_devices > 1 else ''}"
        )


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.2g} s"
    if seconds < 7200:
        return f"{seconds / 60:.2g} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.2g} h"
    return f"{seconds / 86400:.3g} days"


def estimate_cost(scenario: Scenario, runs: int | None = None, n_devices: int | None = None):
    """:class:`CostEstimate` of a study of ``scenario`` (nothing is built or compiled)."""
    runs = scenario.runs if runs is None else runs
    n_dev = min(n_devices or len(jax.devices()), len(jax.devices()))
    system = get_system(scenario.kind)
    steps = system.steps_per_run(scenario.config)
    if steps is None:
        return CostEstimate(runs, None, n_dev, None)
    per_device = -(-runs // n_dev)
    return CostEstimate(runs, float(steps), n_dev, per_device * steps * system.step_seconds)


LANES_FROM = 64
"""A device batch smaller than this many runs is never padded (see :func:`padded_chunk`)."""


def padded_chunk(chunk: int, n_dev: int, lanes: int = 1) -> int:
    """Runs per compiled call for ``chunk`` requested on ``n_dev`` devices: a whole number of
    runs per device and, for a system whose ``vector_lanes`` is above 1 and from
    ``LANES_FROM`` runs per device on, a multiple of ``lanes`` per device.

    XLA on CPU vectorises a batch's elementwise loops over whole SIMD registers: a
    ``deep-impact-los`` device batch that was not a multiple of the vector width (4 float64
    with AVX2) ran 1.6x slower per run (2 devices: 1668 runs per device 261 us per run, 1669
    runs 415 us). The extra runs are computed with their own keys and dropped; no run's outcome
    depends on the padding. A loop dominated by lock-step waiting (the capsule's corrector)
    gains nothing and pays for the extra runs, hence the per-system choice.
    """
    per_device = -(-chunk // n_dev)
    if lanes > 1 and per_device >= LANES_FROM:
        per_device = -(-per_device // lanes) * lanes
    return per_device * n_dev


def _physical_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not POSIX: assume 8 GiB
        return 8 << 30


def _check_memory(compiled, chunk: int, limit_fraction: float) -> None:
    """Refuse a chunk whose compiled program needs more than ``limit_fraction`` of the
    machine's memory, before it runs (checked on the compiled executable's own figures)."""
    try:
        stats = compiled.memory_analysis()
        need = stats.temp_size_in_bytes + stats.argument_size_in_bytes + stats.output_size_in_bytes
    except Exception:  # a backend without memory analysis: nothing to check
        return
    limit = limit_fraction * _physical_memory()
    if need > limit:
        per_run = need / chunk
        raise ScenarioError(
            f"chunk_size: {chunk} runs need {need / 1e9:.3g} GB ({per_run / 1e3:.3g} kB per run),"
            f" more than {limit_fraction:.0%} of this machine's {_physical_memory() / 1e9:.3g} GB;"
            f" allowed: chunk_size <= {max(int(limit // per_run), 1)} (CLI --chunk-size)"
        )


_COMPILED: dict = {}


def _compile(system, fn, n_dev, sim, law, seed_arr, chunk):
    """Ahead-of-time compile (timed), reusing an executable compiled for the same structure.

    The cache key is everything the executable depends on: the system, the device count, the
    chunk size and the tree structure (with static fields), shapes and dtypes of (sim, law, seed).
    Gains and scenario values are arguments, so a new value does not recompile.
    """
    leaves, treedef = jax.tree_util.tree_flatten((sim, law, seed_arr))
    key = (system, n_dev, chunk, treedef, tuple((jnp.shape(x), jnp.result_type(x)) for x in leaves))
    if key in _COMPILED:
        return _COMPILED[key], 0.0
    t0 = time.perf_counter()
    compiled = fn.lower(sim, law, seed_arr, jnp.arange(chunk)).compile()
    compile_s = time.perf_counter() - t0
    if len(_COMPILED) >= 32:
        _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[key] = compiled
    return compiled, compile_s


def _run_local(scenario, system, seed, todo, chunk, n_devices, max_memory_fraction, finished):
    """The chunks ``todo`` on this process's devices; returns the compile time and the
    ``time.perf_counter()`` at which the runs started."""
    sim, law = build(scenario)
    fn, n_dev = batch_function(system, n_devices)
    seed_arr = seed if isinstance(seed, DrawPlan) else jnp.asarray(seed, dtype=jnp.uint32)
    compiled, compile_s = _compile(system, fn, n_dev, sim, law, seed_arr, chunk)
    _check_memory(compiled, chunk, max_memory_fraction)

    def launch(c):
        return compiled(sim, law, seed_arr, jnp.arange(c * chunk, (c + 1) * chunk))

    # One chunk ahead: a device that finishes its share of a chunk starts on the next while
    # the other devices and the host are still on this one.
    t0 = time.perf_counter()
    if todo:
        pending = launch(todo[0])
    for k, c in enumerate(todo):
        out = pending
        if k + 1 < len(todo):
            pending = launch(todo[k + 1])
        finished(c, out._asdict())
    return compile_s, t0


_BUILT: dict = {}


def run_chunk(scenario: Scenario, seed: int, start: int, stop: int, chunk: int):
    """Runs ``start .. stop-1`` of a study on this process's devices (a Dask worker's task):
    ``(outcomes as numpy arrays, compile time)``. The scenario is built and the chunk compiled
    once per process and chunk size (and read from JAX's persistent compilation cache when
    the worker was started with one)."""
    system = get_system(scenario.kind)
    text = scenario.to_toml()
    if text not in _BUILT:
        _BUILT.clear()
        _BUILT[text] = build(scenario)
    sim, law = _BUILT[text]
    fn, n_dev = batch_function(system)
    padded = padded_chunk(chunk, n_dev, system.vector_lanes)
    seed_arr = jnp.asarray(seed, dtype=jnp.uint32)
    compiled, compile_s = _compile(system, fn, n_dev, sim, law, seed_arr, padded)
    out = compiled(sim, law, seed_arr, jnp.arange(start, start + padded))
    return {k: np.asarray(v)[: stop - start] for k, v in out._asdict().items()}, compile_s


def local_cluster(workers: int):
    """A ``dask.distributed`` client of a local cluster of ``workers`` processes, the cores
    split between them (``GNC_JAX_HOST_DEVICES``), with JAX's persistent compilation cache."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise ScenarioError(
            "workers: needs dask.distributed; allowed: pip install 'gnc_jax[cluster]'"
        ) from None
    import pathlib

    per = max(1, (os.cpu_count() or 1) // workers)
    cache = os.environ.get(
        "JAX_COMPILATION_CACHE_DIR", str(pathlib.Path.home() / ".cache" / "gnc_jax" / "xla")
    )
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        env={"GNC_JAX_HOST_DEVICES": str(per), "JAX_COMPILATION_CACHE_DIR": cache},
    )
    return Client(cluster)


def _run_distributed(scenario, seed, todo, bounds, chunk, client, workers, finished):
    """The chunks ``todo`` as tasks of a Dask client; returns ``(compile time, errors,
    workers, time.perf_counter() once the cluster was up)``. A lost worker's tasks are rerun
    elsewhere by Dask; a chunk that raises is reported and the others go on."""
    from dask.distributed import as_completed

    own = client is None
    if own:
        client = local_cluster(workers)
    try:
        n_workers = len(client.scheduler_info()["workers"])
        t0 = time.perf_counter()
        futures = {
            client.submit(run_chunk, scenario, seed, *bounds[c], chunk, pure=False): c for c in todo
        }
        compile_s, errors = 0.0, []
        for fut in as_completed(futures):
            c = futures[fut]
            if fut.status == "error":
                exc = fut.exception()
                errors.append(
                    dict(chunk=c, runs=list(bounds[c]), error=f"{type(exc).__name__}: {exc}")
                )
                continue
            outcomes, cs = fut.result()
            compile_s = max(compile_s, cs)
            finished(c, outcomes)
        return compile_s, errors, n_workers, t0
    except BaseException:
        for fut in list(locals().get("futures", ())):
            fut.cancel()
        raise
    finally:
        if own:
            cluster = client.cluster
            client.close()
            cluster.close()


@functools.lru_cache(maxsize=16)
def _jitted_single(system: AbstractSystem):
    return jax.jit(system.simulate, static_argnames=("record",))


def simulate_one(scenario: Scenario, index: int = 0, seed: int | None = None, record=True):
    """Run ``index`` of a study alone (same key as in the batch), with its trace."""
    system = get_system(scenario.kind)
    sim, law = build(scenario)
    seed = scenario.seed if seed is None else seed
    out, trace = _jitted_single(system)(sim, law, run_key(seed, index), record=record)
    return jax.tree_util.tree_map(np.asarray, out), jax.tree_util.tree_map(np.asarray, trace)


def simulate_traces(
    scenario: Scenario, indices, seed: int | None = None, every: int = 1, chunk_size: int = 100
):
    """Traces of runs ``indices`` (same keys as in the batch), ``vmap``ped in chunks.

    Returns ``(outcomes, traces)`` as dicts of numpy arrays with the run on the first axis;
    the traces keep every ``every``-th sample along time to bound memory.
    """
    system = get_system(scenario.kind)
    sim, law = build(scenario)
    seed = scenario.seed if seed is None else seed
    fn = _batched_traces(system, every)
    indices = np.asarray(indices, dtype=int)
    outs, traces = [], []
    for start in range(0, len(indices), chunk_size):
        idx = indices[start : start + chunk_size]
        pad = np.pad(idx, (0, chunk_size - len(idx)), mode="edge")  # one compiled shape
        o, tr = jax.tree_util.tree_map(np.asarray, fn(sim, law, seed, jnp.asarray(pad)))
        outs.append({k: v[: len(idx)] for k, v in o._asdict().items()})
        traces.append({k: v[: len(idx)] for k, v in tr._asdict().items()})
    cat = lambda parts: {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}  # noqa: E731
    return cat(outs), cat(traces)


@functools.lru_cache(maxsize=16)
def _batched_traces(system: AbstractSystem, every: int):
    def run(sim, law, seed, i):
        out, trace = system.simulate(sim, law, run_key(seed, i), record=True)
        return out, jax.tree_util.tree_map(lambda x: x[::every], trace)

    return jax.jit(jax.vmap(run, in_axes=(None, None, None, 0)))
