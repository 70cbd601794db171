"""Monte Carlo studies: :func:`run_study` validates the request, checks the cost, splits the runs
into chunks, runs them on the engine (:mod:`gnc_jax.montecarlo`) and keeps their outcomes in
memory or in a study directory (:mod:`gnc_jax.store`); :class:`Study` is the result.

Run ``i`` of a study with root seed ``s`` always uses the key
``jax.random.fold_in(jax.random.key(s), i)``, so a run's result never depends on the batch size,
the chunking, the devices, the workers or on resuming.
"""

import dataclasses
import hashlib
import sys
import time
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from ._status import Status
from .backend import describe, require, select
from .montecarlo import (
    ANNOUNCE_S,
    MAX_HOURS,
    MAX_MEMORY_FRACTION,
    LocalPlan,
    _compile_local,
    _run_distributed,
    _run_local,
    build_on,
    study_layout,
    worker_environment,
)
from .planner import estimate_cost, plan_chunk
from .results import save_study, summarize
from .scenario import Scenario, ScenarioError
from .store import StudyStore, check_directory, chunk_files, chunks_left, code_version
from .systems.base import get_system


@dataclasses.dataclass
class Study:
    """Result of a Monte Carlo study.

    Attributes:
        outcomes: per-run arrays keyed by outcome field (first axis = run index); for a study
            written to a directory (``run_study(..., out=DIR)``) they are read from its chunk
            files when first used, and :meth:`summary` reads only the columns it needs.
        compile_s: ahead-of-time compilation time (0 when an executable compiled earlier in
            this process was reused); wall_s: the study's wall time after compilation, less
            the time spent writing chunks to the study directory (``write_s``).
        path: the study directory, if written to one; chunk_errors: chunks that raised
            (``{"chunk", "runs": [start, stop], "error"}``), their runs missing from the study.
        device: where it ran (:func:`gnc_jax.backend.describe`: platform, device kind and
            count, memory, jax/jaxlib/CUDA versions); write_s: seconds spent writing the
            chunk files, summary and scenario to the study directory (0 without one).
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
    device: dict | None = None
    write_s: float = 0.0

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
    device: str | None = None,
    draws=None,
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
        n_devices: devices to shard over (default: all of the chosen platform's).
        max_hours: refuse (:class:`~gnc_jax.scenario.ScenarioError`, before the reference
            design or compilation) a study whose :func:`estimate_cost` exceeds this many hours.
        max_memory_fraction: bound on a compiled batch's memory, as a fraction of one
            device's (a GPU's allocator limit; on the CPU the machine's physical memory),
            checked after compilation, before any run and before ``out`` is written: a chunk
            size the planner chose is halved until it fits, a ``chunk_size`` given here is
            refused.
        out: a study directory (``gnc_jax.store``): each chunk is written there as soon as it
            finishes, the summary and scenario last; the returned study reads its outcomes
            from there. A directory holding another study is refused before anything is built.
            The scenario is built (a capsule's reach check and reference design) and its batch
            compiled (the memory bound) before the directory is written, so a study refused
            there leaves no partial study behind.
        resume: continue the study already in ``out`` (same scenario, seed, runs, chunk size
            and code version): finished chunks are kept, missing or damaged ones computed.
        overwrite: replace a study already in ``out`` as a whole.
        client: a ``dask.distributed.Client``: the chunks run as tasks on its workers (sent
            the scenario as built here; each worker compiles once per process; results come
            back to this process).
        workers: start a local Dask cluster of this many worker processes for the study
            (the cores are split between them).
        device: ``"cpu"``, ``"gpu"`` or ``"auto"`` (default: JAX's default backend, a GPU
            where JAX finds one); a GPU asked for where there is none is refused
            (:mod:`gnc_jax.backend`). On a GPU a default chunk is as large as fits its memory.
        draws: a :class:`~gnc_jax._random.DrawPlan` whose ``seed_a`` is ``seed``: route each
            error source's draws between the runs of two seeds and scale them (the error
            budget, :mod:`gnc_jax.budget`); in memory on this process only.

    A study estimated to take more than ``ANNOUNCE_S`` seconds prints its estimate to stderr
    and runs in chunks of about 10 s each so that the progress bar has an ETA. Per-run
    outcomes do not depend on the chunk size, the devices, the workers or on resuming.
    Ctrl-C stops between chunks; the chunks already written to ``out`` are kept.
    """
    runs = scenario.runs if runs is None else runs
    seed = scenario.seed if seed is None else seed
    _check_request(
        runs, seed, chunk_size, out, resume, overwrite, client, workers, max_hours,
        max_memory_fraction,
    )  # fmt: skip
    if workers is not None:  # before anything is built: one line naming the extra
        require("dask.distributed", "workers")
    if draws is not None and (out is not None or client is not None or workers is not None):
        raise ScenarioError(
            "draws: routed draws run in memory on this process; allowed: without out, client "
            "or workers"
        )
    system = get_system(scenario.kind)
    backend = select(device)
    cost = _checked_cost(scenario, runs, n_devices, max_hours, backend)
    fixed = chunk_size is not None
    if resume and chunk_size is None:
        chunk_size = _recorded_chunk_size(out)
    announce = cost.seconds is not None and cost.seconds > ANNOUNCE_S and progress is not False
    if announce:
        print(f"{scenario.name}: estimated {cost}", file=sys.stderr)
    distributed = client is not None or workers is not None
    n_dev = min(n_devices or backend.count, backend.count)
    chunk = plan_chunk(
        system, runs, chunk_size, backend, _chunk_devices(backend, n_dev, client, workers), cost,
        announce, distributed, max_memory_fraction, _worker_count(client, workers),
    )  # fmt: skip
    n_chunks = -(-runs // chunk)
    bounds = [(c * chunk, min((c + 1) * chunk, runs)) for c in range(n_chunks)]
    manifest = None if out is None else _manifest(scenario, seed, runs, chunk)
    if out is not None:
        check_directory(out, manifest, resume, overwrite)
    # The system's checks of the scenario against its models (the capsule's reach check and
    # reference design) and the memory bound on the compiled batch refuse a study before its
    # directory is written: a refused study leaves nothing to resume; a resumed study with no
    # chunk left compiles nothing. Dask workers are sent what was built here and compile their
    # own chunks.
    built = build_on(backend, scenario)
    keys = seed if draws is None else draws
    plan = LocalPlan(backend, n_devices, max_memory_fraction, fixed, None, built)
    todo = chunks_left(out, bounds) if resume else list(range(n_chunks))
    if not distributed and todo:
        with study_layout(system, backend, runs, chunk // n_dev):
            plan = _compile_local(system, keys, chunk, plan)
    store = None if out is None else StudyStore(out, manifest, resume, overwrite)
    try:
        parts, compile_s, wall_s, n_workers, write_s = _run_chunks(
            scenario, system, keys, runs, chunk, bounds, todo, store, progress, announce,
            distributed, plan, client, workers, device,
        )  # fmt: skip
        return _finish(
            scenario, runs, seed, parts, n_chunks, store, compile_s, wall_s, n_dev, chunk,
            n_workers, describe(backend, n_dev), write_s,
        )  # fmt: skip
    finally:
        if store is not None:
            store.close()


def check_seed(seed) -> int:
    """``seed`` when it is a root seed, an integer in [0, 2^32); :class:`ScenarioError`
    naming it otherwise."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ScenarioError(f"seed: {seed!r}; allowed: an integer in [0, 2^32)")
    return seed


def _check_request(
    runs, seed, chunk_size, out, resume, overwrite, client, workers, max_hours,
    max_memory_fraction,
) -> None:  # fmt: skip
    """:class:`ScenarioError` naming the first bad argument of :func:`run_study`."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs <= 0:
        raise ScenarioError(f"runs: {runs!r}; allowed: an integer >= 1")
    check_seed(seed)
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


def _checked_cost(scenario, runs, n_devices, max_hours, backend):
    """The study's :func:`estimate_cost`; :class:`ScenarioError` when over ``max_hours``."""
    cost = estimate_cost(scenario, runs, n_devices, backend)
    if cost.seconds is not None and cost.seconds > max_hours * 3600:
        raise ScenarioError(
            f"cost: {cost}; allowed: at most {max_hours:g} h (raise max_hours, CLI --max-hours, "
            "or use fewer runs or a coarser step)"
        )
    return cost


def _finish(
    scenario, runs, seed, parts, n_chunks, store, compile_s, wall_s, n_dev, chunk, n_workers,
    device, write_s,
):  # fmt: skip
    """The :class:`Study` of the finished chunks: in memory (``parts``), or read from ``store``
    once its summary and scenario are written (their writing counted in ``write_s``)."""
    outcomes = None
    if store is None:
        fields = list(parts[0])
        outcomes = {k: np.concatenate([parts[c][k] for c in range(n_chunks)]) for k in fields}
    study = Study(
        scenario, runs, seed, outcomes, compile_s, wall_s, n_dev, chunk,
        None if store is None else store.path, workers=n_workers, device=device,
        write_s=write_s,
    )  # fmt: skip
    if store is not None:
        t0 = time.perf_counter()
        store.finish(study.summary(), scenario.to_toml())
        study.write_s += time.perf_counter() - t0
    return study


def _manifest(scenario, seed, runs, chunk) -> dict:
    """What a study directory records of the study (:class:`~gnc_jax.store.StudyStore`)."""
    return dict(
        scenario_name=scenario.name,
        kind=scenario.kind,
        scenario_sha256=hashlib.sha256(scenario.to_toml().encode()).hexdigest(),
        seed=seed,
        runs=runs,
        chunk_size=chunk,
        code_version=code_version(),
    )


def _run_chunks(
    scenario, system, seed, runs, chunk, bounds, todo, store, progress, announce, distributed,
    plan, client, workers, device,
):  # fmt: skip
    """The chunks ``todo`` (those not yet in ``store``; a damaged file of one is removed
    first), run locally (``plan``) or on Dask workers with a progress bar; each finished chunk
    goes to ``store`` (else into the returned ``parts``). Returns ``(parts, compile_s, wall_s,
    workers, write_s)``, ``wall_s`` less ``write_s``; :class:`StudyError` if chunks raised."""
    n_chunks = len(bounds)
    if store is not None:
        for c in todo:
            store.discard_chunk(c)
    show = (
        progress if progress is not None else (n_chunks > 1 and (sys.stderr.isatty() or announce))
    )
    bar = tqdm(
        total=runs,
        initial=sum(bounds[c][1] - bounds[c][0] for c in range(n_chunks) if c not in todo),
        desc=scenario.name,
        unit="run",
        disable=not show,
    )
    parts: dict[int, dict] = {}
    write_s = 0.0

    def finished(c, outcomes):
        nonlocal write_s
        start, stop = bounds[c]
        outcomes = {k: np.asarray(v)[: stop - start] for k, v in outcomes.items()}
        _nan_to_status(outcomes)
        if store is not None:
            t_write = time.perf_counter()
            store.write_chunk(c, start, outcomes)
            write_s += time.perf_counter() - t_write
        else:
            parts[c] = outcomes
        bar.update(stop - start)

    t0 = time.perf_counter()
    try:
        if distributed:
            compile_s, errors, n_workers, t0 = _run_distributed(
                scenario, plan.built, seed, todo, bounds, chunk, client, workers, finished,
                device, runs,
            )  # fmt: skip
            t0 += compile_s  # the workers compile first, all at once
        else:
            plan = plan._replace(finished=finished)
            compile_s, t0 = _run_local(system, seed, todo, chunk, plan)
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
    wall_s = time.perf_counter() - t0 - write_s
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
    return parts, compile_s, wall_s, n_workers, write_s


class StudyError(RuntimeError):
    """Chunks of a study raised; ``errors``: ``{"chunk", "runs": [start, stop], "error"}``."""

    def __init__(self, message: str, errors: list):
        super().__init__(message)
        self.errors = errors


def _chunk_devices(backend, n_dev: int, client, workers) -> int:
    """Devices a chunk is planned for: this process's ``n_dev``, or on a local cluster of
    ``workers`` CPU workers (no ``client``) one worker's host devices
    (:func:`~gnc_jax.montecarlo.worker_environment`)."""
    if client is None and workers is not None and backend.platform == "cpu":
        return int(worker_environment(workers, 0)["GNC_JAX_HOST_DEVICES"])
    return n_dev


def _worker_count(client, workers) -> int:
    """Dask workers a study's chunks are spread over (1 when local)."""
    if workers is not None:
        return workers
    if client is not None:
        return max(len(client.nthreads()), 1)
    return 1


def _recorded_chunk_size(out) -> int | None:
    import json
    import pathlib

    from .store import MANIFEST

    try:
        return int(json.loads((pathlib.Path(out) / MANIFEST).read_text())["chunk_size"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
