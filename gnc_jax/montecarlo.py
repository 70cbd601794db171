"""The Monte Carlo engine: one ``vmap``ped single-trajectory simulator, sharded over the
devices of a backend (:mod:`gnc_jax.backend`: the CPU's host devices or a GPU), compiled ahead of
time and run chunk by chunk (locally or on Dask workers), a batch halved where the memory guard
of :mod:`gnc_jax.planner` finds it too large; single runs and traces. :mod:`gnc_jax.study`
builds studies on it.

Run ``i`` of a study with root seed ``s`` always uses the key
``jax.random.fold_in(jax.random.key(s), i)``, so a run's result never depends on the batch size,
the chunking or the number of devices. On the CPU batches are split over the host devices (one
per core, see ``gnc_jax._config``) with ``shard_map``; long studies run in chunks with a
progress bar.
Compilation happens once, ahead of time, and is timed separately from the study.
"""

import contextlib
import functools
import os
import re
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

from ._numerics import (
    explicit_loop_shape,
    for_platform,
    layout_for,
    using_lanes,
    using_loop_shape,
)
from ._random import DrawPlan, plan_key, run_key
from .backend import Backend, placement, require, select
from .planner import (
    LANES_FROM,
    CostEstimate,
    compiled_bytes,
    estimate_cost,
    memory_limit,
    memory_refusal,
    padded_chunk,
)
from .scenario import Scenario
from .systems.base import AbstractSystem, get_system

__all__ = ["LANES_FROM", "CostEstimate", "estimate_cost", "padded_chunk"]  # re-exported


def build(scenario: Scenario):
    """``(params, law)`` of a scenario, built by its system (SI units): what
    :func:`simulate_one` and :func:`run_study` run, for your own loops."""
    return get_system(scenario.kind).build(scenario)


def build_on(backend: Backend, scenario: Scenario):
    """:func:`build` with ``backend`` placing its arrays and computations."""
    with placement(backend):
        return build(scenario)


def batch_function(system: AbstractSystem, n_devices: int | None = None, devices=None):
    """``f(sim, law, seed, indices) -> outcomes`` vmapped over run indices, sharded over devices.

    ``seed``: the root seed, or a :class:`~gnc_jax._random.DrawPlan` that routes each error
    source's draws (the error budget). ``devices``: JAX's default devices unless given (another
    platform's, or the CPU's where the default is a GPU: the program is then always placed on
    them through a mesh, even on one device); ``indices`` must have a length divisible by the
    number of devices.
    """
    placed = devices is not None
    devices = list(devices if placed else jax.devices())
    devices = devices[: n_devices or len(devices)]

    def per_device(sim, law, seed, indices):
        return jax.vmap(lambda i: system.simulate(sim, law, plan_key(seed, i))[0])(indices)

    if len(devices) == 1 and not placed:
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
"""Default bound on a compiled batch's memory, as a fraction of one device's memory (a GPU's
allocator limit; on the CPU the machine's physical memory)."""
ANNOUNCE_S = 30.0
"""A study estimated to run longer than this announces its estimate and shows progress."""


_COMPILED: dict = {}


def structure(tree) -> tuple:
    """What a compiled program depends on of its arguments ``tree``: the tree structure (with
    static fields), and each leaf's shape and dtype; values are arguments, not part of it."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    return treedef, tuple((jnp.shape(x), jnp.result_type(x)) for x in leaves)


def _compile(system, fn, where, sim, law, seed_arr, chunk):
    """Ahead-of-time compile (timed), reusing an executable compiled for the same structure.

    The cache key is everything the executable depends on: the system, ``where`` it runs
    (:func:`_where`: the devices and whether the program is placed on them), the chunk size,
    the loop layout (:class:`~gnc_jax._numerics.LoopShape`: the one set by the caller, else
    the devices' platform default) and the tree structure (with static fields), shapes and
    dtypes of (sim, law, seed). Gains and scenario values are arguments, so a new value does not
    recompile.
    """
    shape = layout_for(where[0][0].platform, system)
    key = (system, where, chunk, shape, structure((sim, law, seed_arr)))
    if key in _COMPILED:
        return _COMPILED[key], 0.0
    t0 = time.perf_counter()
    with using_loop_shape(shape), using_lanes(chunk // len(where[0])):
        compiled = fn.lower(sim, law, seed_arr, jnp.arange(chunk)).compile()
    compile_s = time.perf_counter() - t0
    if len(_COMPILED) >= 32:
        _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[key] = compiled
    return compiled, compile_s


def _check_memory(compiled, batch: int, backend: Backend, fraction: float):
    """``None`` when the compiled batch fits ``fraction`` of a device's memory, else the
    :class:`ScenarioError` that refuses it (checked on the executable's own figures)."""
    need = compiled_bytes(compiled)
    limit = memory_limit(backend, fraction)
    if need is None or need <= limit:
        return None
    return memory_refusal(need, batch, backend, fraction, limit)


def _fitting_batch(system, fn, devices, sim, law, seed_arr, chunk, backend, plan):
    """The compiled batch for chunks of ``chunk`` runs: the chunk itself, or, when it does not
    fit the device's memory and the planner chose it (``plan.fixed`` false), the largest half,
    quarter, ... that fits; ``(compiled, batch, compile_s)``."""
    batch, compile_s = chunk, 0.0
    while True:
        compiled, seconds = _compile(
            system, fn, _where(backend, devices), sim, law, seed_arr, batch
        )
        compile_s += seconds
        refusal = _check_memory(compiled, batch, backend, plan.max_memory_fraction)
        if refusal is None:
            return compiled, batch, compile_s
        if plan.fixed or batch <= len(devices):
            raise refusal
        batch = padded_chunk(-(-batch // 2), len(devices), system.vector_lanes)


class LocalPlan(NamedTuple):
    """How :func:`_run_local` runs: on ``backend`` (``n_devices`` of its devices), a batch
    halved to fit ``max_memory_fraction`` of a device's memory unless ``fixed`` (the user's
    chunk size), calling ``finished(chunk, outcomes)`` as each chunk is done, with the
    scenario's ``(params, law)`` ``built`` on ``backend`` (:func:`build_on`) and the
    ``(executable, batch, compile_s)`` ``compiled`` for it (:func:`_compile_local`)."""

    backend: Backend
    n_devices: int | None
    max_memory_fraction: float
    fixed: bool
    finished: Callable | None
    built: tuple
    compiled: tuple | None = None


def _where(backend: Backend, devices) -> tuple:
    """What an executable is compiled for: the devices, and whether it is placed on them
    (:func:`batch_function`'s mesh for a non-default platform)."""
    return (tuple(devices), not backend.default)


def _placed_devices(backend: Backend):
    """The devices :func:`batch_function` places the program on (``None``: JAX's default)."""
    return None if backend.default else backend.devices


def _seed_array(seed):
    return seed if isinstance(seed, DrawPlan) else jnp.asarray(seed, dtype=jnp.uint32)


def _compile_local(system, seed, chunk, plan: LocalPlan) -> LocalPlan:
    """``plan`` with the batch for chunks of ``chunk`` runs compiled on its devices and
    checked against its memory bound (:func:`_fitting_batch`: a ``fixed`` chunk that does not
    fit raises its :class:`ScenarioError` here, before any run)."""
    with placement(plan.backend):
        sim, law = plan.built
        fn, n_dev = batch_function(system, plan.n_devices, _placed_devices(plan.backend))
        devices = plan.backend.devices[:n_dev]
        compiled = _fitting_batch(
            system, fn, devices, sim, law, _seed_array(seed), chunk, plan.backend, plan
        )
    return plan._replace(compiled=compiled)


def _run_local(system, seed, todo, chunk, plan: LocalPlan):
    """The chunks ``todo`` on this process's devices, with the executable of
    :func:`_compile_local`; returns the compile time and the ``time.perf_counter()`` at which
    the runs started (no compile time and no executable without ``todo``)."""
    if not todo:
        return 0.0, time.perf_counter()
    with placement(plan.backend):
        sim, law = plan.built
        seed_arr = _seed_array(seed)
        compiled, batch, compile_s = plan.compiled

        def launch(c):
            starts = range(c * chunk, (c + 1) * chunk, batch)
            return [compiled(sim, law, seed_arr, jnp.arange(s, s + batch)) for s in starts]

        # One chunk ahead: a device that finishes its share of a chunk starts on the next
        # while the other devices and the host are still on this one.
        t0 = time.perf_counter()
        pending = launch(todo[0])
        for k, c in enumerate(todo):
            outs = pending
            if k + 1 < len(todo):
                pending = launch(todo[k + 1])
            plan.finished(c, _joined(outs))
    return compile_s, t0


def _joined(outs) -> dict:
    """The outcomes of a chunk's batches, as one dict (a chunk is mostly one batch)."""
    if len(outs) == 1:
        return outs[0]._asdict()
    parts = [o._asdict() for o in outs]
    return {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in parts[0]}


def study_layout(system, backend, runs: int, lanes: int):
    """The loop layout a study's chunks compile in where they run (this process, or a Dask
    worker): the system's CPU layout with its ``rare`` path on where the system declares one
    (:attr:`~gnc_jax.systems.AbstractSystem.rare_layout`) and the study of ``runs`` runs, at
    ``lanes`` runs a device, is large enough to repay it; else the default (a layout the
    caller set is kept)."""
    rare = system.rare_layout
    if (
        rare is None
        or explicit_loop_shape() is not None
        or backend.platform != "cpu"
        or runs < rare.min_runs
        or lanes < rare.min_lanes
    ):
        return contextlib.nullcontext()
    return using_loop_shape(for_platform("cpu", system)._replace(rare=rare.fraction))


def run_chunk(
    scenario: Scenario,
    seed: int,
    start: int,
    stop: int,
    chunk: int,
    device: str = "auto",
    *,
    built: tuple,
    study_runs: int | None = None,
):
    """Runs ``start .. stop-1`` of a study on this process's ``device`` (a Dask worker's task):
    ``(outcomes as numpy arrays, compile time)``. ``built``: the scenario's ``(params, law)``
    as the process that submitted the study built them (:func:`build_on`), so no worker
    builds it again (a midcourse nominal's targeting, a capsule's reference design). The chunk
    is compiled once per process, chunk size and layout (and read from JAX's persistent
    compilation cache when the worker was started with one), in the layout a local study of
    ``study_runs`` runs (default: the chunk's) would compile at this process's lanes a device
    (:func:`study_layout`)."""
    system = get_system(scenario.kind)
    backend = select(device)
    with placement(backend):
        sim, law = built
        fn, n_dev = batch_function(system, devices=_placed_devices(backend))
        padded = padded_chunk(chunk, n_dev, system.vector_lanes)
        seed_arr = jnp.asarray(seed, dtype=jnp.uint32)
        where = _where(backend, backend.devices[:n_dev])
        with study_layout(system, backend, study_runs or stop - start, padded // n_dev):
            compiled, compile_s = _compile(system, fn, where, sim, law, seed_arr, padded)
        out = compiled(sim, law, seed_arr, jnp.arange(start, start + padded))
    return {k: np.asarray(v)[: stop - start] for k, v in out._asdict().items()}, compile_s


_HOST_FLAG = "--xla_force_host_platform_device_count"


def worker_environment(workers: int, gpus: int, host_devices: int | None = None) -> dict[str, str]:
    """Environment of each of ``workers`` local worker processes: its host devices
    (``GNC_JAX_HOST_DEVICES`` and ``XLA_FLAGS``), JAX's persistent compilation cache and,
    where there are GPUs, no preallocation and a share of each GPU's memory (JAX's default
    lets every process take 75 % of a GPU on its first computation, so a second worker would
    fail).

    A worker has twice its share of the cores as host devices (at most the cores): while one
    worker is between chunks (receiving a task, sending its outcomes) the other's devices
    keep the cores busy. Measured on 2 cores, 2 workers, ``deep-impact-los`` 40,000 runs,
    warm: 5,634 runs/s with 2 devices a worker, 4,400 with 1 (its best chunk size).
    ``host_devices``: a count of one's own instead."""
    import pathlib

    cores = os.cpu_count() or 1
    per = host_devices or min(cores, 2 * max(1, cores // workers))
    cache = os.environ.get(
        "JAX_COMPILATION_CACHE_DIR", str(pathlib.Path.home() / ".cache" / "gnc_jax" / "xla")
    )
    # The submitting process's XLA_FLAGS name its own host-device count (gnc_jax._config),
    # which a worker inherits and would keep: the worker's count goes in its place.
    flags = re.sub(rf"{_HOST_FLAG}=\S*\s*", "", os.environ.get("XLA_FLAGS", "")).strip()
    env = {
        "GNC_JAX_HOST_DEVICES": str(per),
        "XLA_FLAGS": f"{_HOST_FLAG}={per} {flags}".strip(),
        "JAX_COMPILATION_CACHE_DIR": cache,
    }
    if gpus:
        sharing = max(1, -(-workers // gpus))  # worker processes per GPU
        env["XLA_PYTHON_CLIENT_PREALLOCATE"] = os.environ.get(
            "XLA_PYTHON_CLIENT_PREALLOCATE", "false"
        )
        env["XLA_PYTHON_CLIENT_MEM_FRACTION"] = os.environ.get(
            "XLA_PYTHON_CLIENT_MEM_FRACTION", f"{0.9 / sharing:.3f}"
        )
    return env


def local_cluster(workers: int, option: str = "workers", host_devices: int | None = None):
    """A ``dask.distributed`` client of a local cluster of ``workers`` processes, the cores
    (and GPUs' memory) split between them (:func:`worker_environment`, with its
    ``host_devices``).

    The environment is the workers' before they start (Dask's ``pre-spawn-environ``, also for
    a worker its nanny restarts), not only once they run: a worker process first imports the
    submitting program's main module, and where that imports ``gnc_jax`` (the ``gnc-jax``
    command) JAX is configured then, with the submitting process's device count and without
    the compilation cache. The submitting process's own environment is left as it was."""
    distributed = require("dask.distributed", option)
    import dask

    gpus = len(select("auto").devices) if select("auto").platform == "gpu" else 0
    env = worker_environment(workers, gpus, host_devices)
    before = {k: os.environ.get(k) for k in env}
    spawn = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **env}
    try:
        os.environ.update(env)  # read by each nanny as it is created
        with dask.config.set({"distributed.nanny.pre-spawn-environ": spawn}):
            cluster = distributed.LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                env=env,
            )
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return distributed.Client(cluster)


def _run_distributed(
    scenario, built, seed, todo, bounds, chunk, client, workers, finished, device, runs=None
):  # fmt: skip
    """The chunks ``todo`` of a study of ``runs`` runs as tasks of a Dask client, each shipped
    the scenario's ``built`` ``(params, law)`` (:func:`run_chunk`); returns ``(compile time,
    errors, workers, time.perf_counter() once the cluster was up)``. A lost worker's tasks are
    rerun elsewhere by Dask; a chunk that raises is reported and the others go on."""
    as_completed = require("dask.distributed", "workers").as_completed

    own = client is None
    if own:
        client = local_cluster(workers)
    try:
        n_workers = len(client.scheduler_info()["workers"])
        t0 = time.perf_counter()
        futures = {
            client.submit(
                run_chunk,
                scenario,
                seed,
                *bounds[c],
                chunk,
                device=device,
                built=built,
                study_runs=runs,
                pure=False,
            ): c
            for c in todo
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
def _jitted_single(system: AbstractSystem, shape):  # one jit (and trace cache) per loop layout
    return jax.jit(system.simulate, static_argnames=("record",))


def simulate_one(scenario: Scenario, index: int = 0, seed: int | None = None, record=True):
    """Run ``index`` of a study alone (same key as in the batch), with its trace."""
    system = get_system(scenario.kind)
    sim, law = build(scenario)
    seed = scenario.seed if seed is None else seed
    shape = layout_for(jax.default_backend(), system)
    with using_loop_shape(shape):
        out, trace = _jitted_single(system, shape)(sim, law, run_key(seed, index), record=record)
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
    shape = layout_for(jax.default_backend(), system)
    fn = _batched_traces(system, every, shape)
    indices = np.asarray(indices, dtype=int)
    outs, traces = [], []
    for start in range(0, len(indices), chunk_size):
        idx = indices[start : start + chunk_size]
        pad = np.pad(idx, (0, chunk_size - len(idx)), mode="edge")  # one compiled shape
        with using_loop_shape(shape):
            o, tr = jax.tree_util.tree_map(np.asarray, fn(sim, law, seed, jnp.asarray(pad)))
        outs.append({k: v[: len(idx)] for k, v in o._asdict().items()})
        traces.append({k: v[: len(idx)] for k, v in tr._asdict().items()})
    cat = lambda parts: {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}  # noqa: E731
    return cat(outs), cat(traces)


@functools.lru_cache(maxsize=16)
def _batched_traces(system: AbstractSystem, every: int, shape):
    def run(sim, law, seed, i):
        out, trace = system.simulate(sim, law, run_key(seed, i), record=True)
        return out, jax.tree_util.tree_map(lambda x: x[::every], trace)

    return jax.jit(jax.vmap(run, in_axes=(None, None, None, 0)))
