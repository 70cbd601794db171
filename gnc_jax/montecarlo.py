"""Monte Carlo studies: one ``vmap``ped single-trajectory simulator, sharded over host devices.

Run ``i`` of a study with root seed ``s`` always uses the key
``jax.random.fold_in(jax.random.key(s), i)``, so a run's result never depends on the batch size,
the chunking or the number of devices. Batches are split over the host devices (one per core,
see ``gnc_jax._config``) with ``shard_map``; long studies run in chunks with a progress bar.
Compilation happens once, ahead of time, and is timed separately from the study.
"""

import dataclasses
import functools
import hashlib
import os
import sys
import time
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec
from tqdm.auto import tqdm

from ._status import Status
from .results import save_study, summarize
from .scenario import Scenario, ScenarioError
from .store import chunk_files
from .systems.base import AbstractSystem, get_system


def build(scenario: Scenario):
    """``(params, law)`` of a scenario, built by its system (SI units): what
    :func:`simulate_one` and :func:`run_study` run, for your own loops."""
    return get_system(scenario.kind).build(scenario)


def run_key(seed: int, index):
    """The key of run ``index`` of a study with root seed ``seed``."""
    return jax.random.fold_in(jax.random.key(jnp.asarray(seed, dtype=jnp.uint32)), index)


def batch_function(system: AbstractSystem, n_devices: int | None = None):
    """``f(sim, law, seed, indices) -> outcomes`` vmapped over run indices, sharded over devices.

    ``indices`` must have a length divisible by the number of devices.
    """
    devices = jax.devices()[: n_devices or len(jax.devices())]

    def per_device(sim, law, seed, indices):
        return jax.vmap(lambda i: system.simulate(sim, law, run_key(seed, i))[0])(indices)

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
    chunk size and the tree structure (with static fields), shapes and dtypes of (sim, law).
    Gains and scenario values are arguments, so a new value does not recompile.
    """
    leaves, treedef = jax.tree_util.tree_flatten((sim, law))
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


@dataclasses.dataclass
class Study:
    """Result of a Monte Carlo study.

    Attributes:
        outcomes: per-run arrays keyed by outcome field (first axis = run index); for a study
            written to a directory (``run_study(..., out=DIR)``) they are read from its chunk
            files when first used, and :meth:`summary` reads only the columns it needs.
        compile_s: ahead-of-time compilation time (0 when an executable compiled earlier in
            this process was reused); wall_s: the study's wall time after compilation.
        path: the study directory, if written to one; chunk_errors: chunks that raised
            (``{"chunk", "runs": [start, stop], "error"}``), their runs missing from the study.
    """

    scenario: Scenario
    runs: int
    seed: int
    _outcomes: dict[str, np.ndarray] | None = dataclasses.field(repr=False)
    compile_s: float
    wall_s: float
    n_devices: int
    chunk_size: int
    path: Any = None
    chunk_errors: tuple = ()
    workers: int | None = None

    def __post_init__(self):
        if self._outcomes is None and self.path is None:
            raise ValueError("a Study needs its outcomes or the directory holding them")

    @property
    def outcomes(self) -> dict[str, np.ndarray]:
        return self.columns()

    def columns(self, names=None) -> dict[str, np.ndarray]:
        """The outcome arrays ``names`` (all by default), from memory or the chunk files."""
        if self._outcomes is not None:
            return self._outcomes if names is None else {k: self._outcomes[k] for k in names}
        from .store import read_outcomes

        if names is None:
            self._outcomes = read_outcomes(self.path)
            return self._outcomes
        return read_outcomes(self.path, names)

    @property
    def status(self) -> np.ndarray:
        return self.columns(["status"])["status"]

    @property
    def ok(self) -> np.ndarray:
        return self.status == Status.ok

    def summary(self) -> dict[str, Any]:
        return summarize(self)

    def save(self, out_dir, overwrite: bool = False) -> dict[str, str]:
        """Write the study into ``out_dir`` (the layout of ``gnc_jax.store``); a directory
        that holds another study is refused unless ``overwrite``."""
        return save_study(self, out_dir, overwrite=overwrite)


def _nan_to_status(outcomes: dict[str, np.ndarray]) -> None:
    """Flag any run with a non-finite float outcome as ``nan`` (in place)."""
    bad = np.zeros(outcomes["status"].shape, bool)
    for arr in outcomes.values():
        if np.issubdtype(arr.dtype, np.floating):
            bad |= ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1)
    outcomes["status"] = np.where(
        bad & (outcomes["status"] == Status.ok), Status.nan, outcomes["status"]
    ).astype(np.int32)


def run_study(
    scenario: Scenario,
    runs: int | None = None,
    seed: int | None = None,
    chunk_size: int | None = None,
    progress: bool | None = None,
    n_devices: int | None = None,
    max_hours: float = MAX_HOURS,
    max_memory_fraction: float = MAX_MEMORY_FRACTION,
    out=None,
    resume: bool = False,
    overwrite: bool = False,
    client=None,
    workers: int | None = None,
) -> Study:
    """Run a Monte Carlo study of ``scenario``.

    Args:
        scenario: from :func:`gnc_jax.load_scenario`.
        runs: number of runs (default: the scenario's paper run count).
        seed: root seed (default: the scenario's).
        chunk_size: runs per compiled call (default: equal chunks of at most the system's
            ``chunk_per_device`` runs per device, or 1024 runs; a resumed study keeps its own).
        progress: show a progress bar (default: when stderr is a terminal and there are
            several chunks).
        n_devices: host devices to shard over (default: all).
        max_hours: refuse (:class:`~gnc_jax.scenario.ScenarioError`, before the reference
            design or compilation) a study whose :func:`estimate_cost` exceeds this many hours.
        max_memory_fraction: refuse a chunk whose compiled program needs more than this
            fraction of the machine's physical memory (checked after compilation, before any
            run).
        out: a study directory (``gnc_jax.store``): each chunk is written there as soon as it
            finishes, the summary and scenario last; the returned study reads its outcomes
            from there. A directory holding another study is refused.
        resume: continue the study already in ``out`` (same scenario, seed, runs, chunk size
            and code version): finished chunks are kept, missing or damaged ones computed.
        overwrite: replace a study already in ``out`` as a whole.
        client: a ``dask.distributed.Client``: the chunks run as tasks on its workers (each
            worker compiles once per process; results come back to this process).
        workers: start a local Dask cluster of this many worker processes for the study
            (the cores are split between them).

    A study estimated to take more than ``ANNOUNCE_S`` seconds prints its estimate to stderr
    and runs in chunks of about 10 s each so that the progress bar has an ETA. Per-run
    outcomes do not depend on the chunk size, the devices, the workers or on resuming.
    Ctrl-C stops between chunks; the chunks already written to ``out`` are kept.
    """
    runs = scenario.runs if runs is None else runs
    seed = scenario.seed if seed is None else seed
    if isinstance(runs, bool) or not isinstance(runs, int) or runs <= 0:
        raise ScenarioError(f"runs: {runs!r}; allowed: an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ScenarioError(f"seed: {seed!r}; allowed: an integer in [0, 2^32)")
    if chunk_size is not None and (
        isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size <= 0
    ):
        raise ScenarioError(f"chunk_size: {chunk_size!r}; allowed: an integer >= 1")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers <= 0
    ):
        raise ScenarioError(f"workers: {workers!r}; allowed: an integer >= 1")
    if client is not None and workers is not None:
        raise ScenarioError("workers: given with a client; allowed: one of client or workers")
    if (resume or overwrite) and out is None:
        raise ScenarioError("resume/overwrite: no study directory; allowed: with out=DIR")
    if resume and overwrite:
        raise ScenarioError("resume and overwrite: both given; allowed: one of them")
    for name, value, hi in (
        ("max_hours", max_hours, None),
        ("max_memory_fraction", max_memory_fraction, 1.0),
    ):
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not (value > 0 and (hi is None or value <= hi))
        ):
            raise ScenarioError(
                f"{name}: {value!r}; allowed: a number > 0" + (f" and <= {hi:g}" if hi else "")
            )
    system = get_system(scenario.kind)
    cost = estimate_cost(scenario, runs, n_devices)
    if cost.seconds is not None and cost.seconds > max_hours * 3600:
        raise ScenarioError(
            f"cost: {cost}; allowed: at most {max_hours:g} h (raise max_hours, CLI --max-hours, "
            "or use fewer runs or a coarser step)"
        )
    if resume and chunk_size is None:
        chunk_size = _recorded_chunk_size(out)
    announce = cost.seconds is not None and cost.seconds > ANNOUNCE_S and progress is not False
    if announce:
        print(f"{scenario.name}: estimated {cost}", file=sys.stderr)
    distributed = client is not None or workers is not None
    n_dev = min(n_devices or len(jax.devices()), len(jax.devices()))
    default_chunk = system.chunk_per_device * n_dev if system.chunk_per_device else 1024
    if chunk_size is None and announce:  # chunks of about 10 s: a progress bar with an ETA
        default_chunk = int(max(1, min(default_chunk, 10.0 * runs / cost.seconds)))
    chunk = min(runs, chunk_size or default_chunk)
    if chunk_size is None:  # equal chunks: the last one is not mostly padding
        chunk = -(-runs // -(-runs // chunk))
    if not distributed:
        chunk = padded_chunk(chunk, n_dev, system.vector_lanes)
    n_chunks = -(-runs // chunk)
    bounds = [(c * chunk, min((c + 1) * chunk, runs)) for c in range(n_chunks)]

    store = None
    if out is not None:
        from .store import StudyStore, code_version

        manifest = dict(
            scenario_name=scenario.name,
            kind=scenario.kind,
            scenario_sha256=hashlib.sha256(scenario.to_toml().encode()).hexdigest(),
            seed=seed,
            runs=runs,
            chunk_size=chunk,
            code_version=code_version(),
        )
        store = StudyStore(out, manifest, resume=resume, overwrite=overwrite)
    try:
        todo = [c for c in range(n_chunks) if store is None or not store.valid_chunk(c, *bounds[c])]
        show = (
            progress
            if progress is not None
            else (n_chunks > 1 and (sys.stderr.isatty() or announce))
        )
        bar = tqdm(
            total=runs,
            initial=sum(bounds[c][1] - bounds[c][0] for c in range(n_chunks) if c not in todo),
            desc=scenario.name,
            unit="run",
            disable=not show,
        )
        parts: dict[int, dict] = {}

        def finished(c, outcomes):
            start, stop = bounds[c]
            outcomes = {k: np.asarray(v)[: stop - start] for k, v in outcomes.items()}
            _nan_to_status(outcomes)
            if store is not None:
                store.write_chunk(c, start, outcomes)
            else:
                parts[c] = outcomes
            bar.update(stop - start)

        t0 = time.perf_counter()
        try:
            if distributed:
                compile_s, errors, n_workers, t0 = _run_distributed(
                    scenario, seed, todo, bounds, chunk, client, workers, finished
                )
                t0 += compile_s  # the workers compile first, all at once
            else:
                compile_s, t0 = _run_local(
                    scenario, system, seed, todo, chunk, n_devices, max_memory_fraction, finished
                )
                errors, n_workers = [], None
        except KeyboardInterrupt:
            if store is not None:
                kept = len(chunk_files(store.path))
                print(
                    f"{scenario.name}: interrupted; {kept} of {n_chunks} chunks kept in "
                    f"{store.runs_dir} (the same command with --resume continues)",
                    file=sys.stderr,
                )
            raise
        finally:
            bar.close()
        wall_s = time.perf_counter() - t0
        if errors:
            where = f"; the other chunks are in {store.runs_dir}, --resume retries" if store else ""
            raise StudyError(
                f"{scenario.name}: {len(errors)} of {n_chunks} chunks raised: "
                + "; ".join(
                    f"chunk {e['chunk']} (runs {e['runs'][0]}..{e['runs'][1] - 1}): {e['error']}"
                    for e in errors[:3]
                )
                + where,
                errors,
            )
        if store is None:
            fields = list(parts[0])
            outcomes = {k: np.concatenate([parts[c][k] for c in range(n_chunks)]) for k in fields}
            return Study(
                scenario, runs, seed, outcomes, compile_s, wall_s, n_dev, chunk, workers=n_workers
            )
        study = Study(
            scenario,
            runs,
            seed,
            None,
            compile_s,
            wall_s,
            n_dev,
            chunk,
            store.path,
            workers=n_workers,
        )
        store.finish(study.summary(), scenario.to_toml())
        return study
    finally:
        if store is not None:
            store.close()


class StudyError(RuntimeError):
    """Chunks of a study raised; ``errors``: ``{"chunk", "runs": [start, stop], "error"}``."""

    def __init__(self, message: str, errors: list):
        super().__init__(message)
        self.errors = errors


def _recorded_chunk_size(out) -> int | None:
    import json
    import pathlib

    from .store import MANIFEST

    try:
        return int(json.loads((pathlib.Path(out) / MANIFEST).read_text())["chunk_size"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _run_local(scenario, system, seed, todo, chunk, n_devices, max_memory_fraction, finished):
    """The chunks ``todo`` on this process's devices; returns the compile time and the
    ``time.perf_counter()`` at which the runs started."""
    sim, law = build(scenario)
    fn, n_dev = batch_function(system, n_devices)
    seed_arr = jnp.asarray(seed, dtype=jnp.uint32)
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
