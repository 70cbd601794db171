"""The planner of a study, per backend: its cost estimate, its chunk size and its memory guard.

* **Cost** (:func:`estimate_cost`): each system's :class:`~gnc_jax.systems.base.StepCost` on
  the study's platform, a throughput term (runs per device x steps x seconds per run-step)
  plus a latency term (steps x seconds per step, what a GPU pays whatever the batch). A
  platform the system was not calibrated on has no estimate (``seconds is None``), never the
  CPU's figure.
* **Chunks** (:func:`plan_chunk`): on the CPU, equal chunks of at most the system's
  ``chunk_per_device`` runs per device (a batch that fits the cores' caches), of about 10 s
  each when the study is announced; on a GPU, as large as the device's memory allows (the
  system's ``run_bytes``) and at most ``GPU_BATCH_BYTES`` per chunk (a larger batch runs no
  faster per run), split further only for a progress bar, and only as far as the latency term
  stays under a tenth of the estimate. On Dask, a study of at least as many runs as workers
  has at least one chunk per worker: a chunk is one worker's task.
* **Memory** (:func:`compiled_bytes`, :func:`memory_refusal`): the compiled executable's own
  figure against ``max_memory_fraction`` of one device's memory (a GPU's allocator limit, the
  CPU's physical memory); :func:`gnc_jax.run_study` halves a batch it chose itself and refuses
  one the user asked for.
"""

import dataclasses

from .backend import Backend, select
from .scenario import Scenario, ScenarioError
from .systems.base import AbstractSystem, get_system

PROGRESS_CHUNK_S = 10.0
"""An announced study runs in chunks of about this many seconds (a progress bar with an ETA)."""
GPU_BATCH_BYTES = 2e9
"""On a GPU, a default chunk holds at most this many bytes of batch (the system's ``run_bytes``
per run): past it a batch runs no faster per run. Measured on an H100, ``deep-impact-los``
1,000,000 runs in chunks of 125k, 250k, 500k and 1M runs (peak 1.0, 2.1, 4.2, 8.1 GB):
3.84, 3.91, 4.68 and 5.37 s."""
LATENCY_SHARE = 0.1
"""On a GPU, progress chunks are only cut while their added latency (a latency term per chunk
after the first) stays under this share of the estimate."""


@dataclasses.dataclass(frozen=True)
class CostEstimate:
    """What a study will cost, estimated from the scenario alone (before any compilation).

    Attributes:
        runs: runs in the study; steps_per_run: simulation steps of one run (the system's
        :meth:`~gnc_jax.systems.AbstractSystem.steps_per_run`; ``None`` when unknown);
        n_devices: devices the runs are split over; seconds: estimated wall time after
        compilation (within a factor of about 3 where calibrated; ``None``: unknown);
        platform: ``"cpu"`` or ``"gpu"``; latency_s: the latency term within ``seconds``;
        source: where the cost model was measured.
    """

    runs: int
    steps_per_run: float | None
    n_devices: int
    seconds: float | None
    platform: str = "cpu"
    latency_s: float = 0.0
    source: str = ""

    def __str__(self) -> str:
        if self.steps_per_run is None:
            return f"{self.runs} runs (no cost model for this system)"
        steps = (
            f"{self.runs} runs x {self.steps_per_run:.3g} steps = "
            f"{self.runs * self.steps_per_run:.3g} steps"
        )
        devices = f"{self.n_devices} {'gpu ' if self.platform == 'gpu' else ''}device" + (
            "s" if self.n_devices > 1 else ""
        )
        if self.seconds is None:
            return (
                f"{steps}, time unknown on {devices} (this system has no {self.platform} "
                f"calibration; benchmarks/cost_calibration.py --device {self.platform} "
                "measures one)"
            )
        latency = (
            f" ({duration_text(self.latency_s)} of it sequential-step latency)"
            if self.latency_s > 0
            else ""
        )
        return f"{steps}, about {duration_text(self.seconds)} on {devices}{latency}"


def duration_text(seconds: float) -> str:
    """``seconds`` in the unit a reader takes in at once (s, min, h or days)."""
    if seconds < 120:
        return f"{seconds:.2g} s"
    if seconds < 7200:
        return f"{seconds / 60:.2g} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.2g} h"
    return f"{seconds / 86400:.3g} days"


def estimate_cost(
    scenario: Scenario,
    runs: int | None = None,
    n_devices: int | None = None,
    device: "str | Backend | None" = None,
):
    """:class:`CostEstimate` of a study of ``scenario`` on ``device`` (``"cpu"``, ``"gpu"``,
    ``"auto"``/``None`` or a :class:`~gnc_jax.backend.Backend`); nothing is built or compiled."""
    runs = scenario.runs if runs is None else runs
    backend = device if isinstance(device, Backend) else select(device)
    n_dev = min(n_devices or backend.count, backend.count)
    system = get_system(scenario.kind)
    steps = system.steps_per_run(scenario.config)
    if steps is None:
        return CostEstimate(runs, None, n_dev, None, backend.platform)
    cost = system.step_cost(backend.platform)
    if cost is None:
        return CostEstimate(runs, float(steps), n_dev, None, backend.platform)
    per_device = -(-runs // n_dev)
    latency = steps * cost.step_latency_s
    seconds = per_device * steps * cost.run_step_s + latency
    return CostEstimate(runs, float(steps), n_dev, seconds, backend.platform, latency, cost.source)


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


def memory_limit(backend: Backend, fraction: float) -> float:
    """Bytes a compiled batch may need on ``backend``: ``fraction`` of one device's memory
    (the CPU's host devices share the machine's, so there it is the whole batch's bound)."""
    return fraction * (backend.memory_bytes or 0) if backend.memory_bytes else float("inf")


def plan_chunk(
    system: AbstractSystem,
    runs: int,
    chunk_size: int | None,
    backend: Backend,
    n_dev: int,
    cost: CostEstimate,
    announce: bool,
    distributed: bool,
    max_memory_fraction: float = 0.5,
    workers: int = 1,
) -> int:
    """Runs per chunk: ``chunk_size`` if given, else the backend's plan (module docstring);
    equal chunks, padded for the devices when local; on ``workers`` Dask workers at least one
    chunk per worker."""
    if backend.platform == "cpu":
        default_chunk = system.chunk_per_device * n_dev if system.chunk_per_device else 1024
        if chunk_size is None and announce:  # chunks of about 10 s: a progress bar with an ETA
            default_chunk = int(max(1, min(default_chunk, PROGRESS_CHUNK_S * runs / cost.seconds)))
        lanes = system.vector_lanes
    else:
        default_chunk = _device_chunk(
            system, runs, backend, n_dev, cost, announce, max_memory_fraction
        )
        lanes = 1
    if distributed:  # a chunk is one worker's task: none of them idle
        default_chunk = min(default_chunk, -(-runs // max(workers, 1)))
    chunk = min(runs, chunk_size or default_chunk)
    if chunk_size is None:  # equal chunks: the last one is not mostly padding
        chunk = -(-runs // -(-runs // chunk))
    if not distributed:
        chunk = padded_chunk(chunk, n_dev, lanes)
    return chunk


def _device_chunk(system, runs, backend, n_dev, cost, announce, max_memory_fraction) -> int:
    """A GPU's default chunk: all runs that fit ``max_memory_fraction`` of each device's
    memory and ``GPU_BATCH_BYTES``, cut for a progress bar only where the latency it adds is
    under ``LATENCY_SHARE``."""
    # run_bytes is the CPU executable's figure (deep-impact-los: 15 kB per run, the H100's
    # peak 8 kB); the GPU executable's own figure is checked once it is compiled
    fits = min(memory_limit(backend, max_memory_fraction), GPU_BATCH_BYTES) / system.run_bytes
    chunk = int(max(1, min(runs, fits * n_dev)))
    if announce and cost.seconds is not None:
        n = (cost.seconds - cost.latency_s) / PROGRESS_CHUNK_S
        if cost.latency_s > 0:  # each chunk after the first adds one latency term
            n = min(n, 1 + LATENCY_SHARE * cost.seconds / cost.latency_s)
        chunk = min(chunk, -(-runs // max(int(n), 1)))
    return chunk


def compiled_bytes(compiled) -> int | None:
    """Device memory a compiled executable needs (temporaries, arguments and outputs);
    ``None`` where the backend does not say."""
    try:
        stats = compiled.memory_analysis()
        return stats.temp_size_in_bytes + stats.argument_size_in_bytes + stats.output_size_in_bytes
    except Exception:  # a backend without memory analysis: nothing to check
        return None


def memory_refusal(
    need: int, chunk: int, backend: Backend, fraction: float, limit: float
) -> ScenarioError:
    """The one-line refusal of a chunk of ``chunk`` runs that needs ``need`` bytes."""
    per_run = need / chunk
    where = "this machine's" if backend.platform == "cpu" else f"the {backend.device_kind}'s"
    return ScenarioError(
        f"chunk_size: {chunk} runs need {need / 1e9:.3g} GB ({per_run / 1e3:.3g} kB per run),"
        f" more than {fraction:.0%} of {where} {(backend.memory_bytes or 0) / 1e9:.3g} GB;"
        f" allowed: chunk_size <= {max(int(limit // per_run), 1)} (CLI --chunk-size)"
    )
