"""The system contract: one abstract class, one registry.

A *system* (the impactor, the capsule, the midcourse transfer, the intercept, or one a user
adds) is everything gnc_jax needs to run a scenario of that kind:

* its scenario schema — the file sections with units, ranges, defaults and meaning — plus the
  ``[guidance.<law>]`` table of each law of its guidance family (derived from the laws' declared
  parameters) and its cross-field checks;
* ``build(scenario) -> (params, law)``: the scenario data as a pytree (SI units) and the law;
* ``simulate(params, law, key, record=False) -> (outcome, trace)``: one run, pure and jit-able;
  ``outcome`` a NamedTuple whose first field is ``status``;
* ``statistics(outcomes, ok)``: its summary statistics over the ``ok`` runs;
* ``figure_traces(summary, runs, scenario)`` and ``figures(summary, runs, scenario, out,
  traces)``: the runs its report figures draw (simulated by the report layer) and the figures;
* ``paper_labels``: how the published metrics read in ``gnc-jax reproduce``;
* ``tunable`` and ``metrics``: the scenario names of its tunable leaves and the summary keys
  that tuning objectives and envelope maps read;
* ``example`` and ``test_overrides``: a scenario and the overrides that make it cheap, with
  which the family tests exercise every registered system and law.

Loader, Monte Carlo, results, report, reproduction and the CLI ask the registry
(:func:`get_system`); nothing else tests a scenario's kind. A new system is one subclass and one
:func:`register_system` call, from inside the package or from a user's code.
"""

import abc
import importlib
import importlib.metadata
import os
from collections.abc import Collection
from typing import Any, ClassVar, NamedTuple

from ..params import declared_params, file_name, schema_of
from ..schema import Field, ScenarioError, Schema, validate

_REGISTRY: dict[str, "AbstractSystem"] = {}
_RENAMED = {"pn": "intercept"}  # kinds of earlier versions, named in the error


class TraceRequest(NamedTuple):
    """Runs that a system's figures draw, simulated by the report layer and handed to
    :meth:`AbstractSystem.figures` (the figures never run the Monte Carlo themselves).

    Attributes:
        indices: run indices of the study (the study's keys, :func:`gnc_jax.run_key`).
        overrides: scenario overrides for these runs (e.g. an error-free case); ``None``: none.
        seed: root seed; ``None``: the study's.
        every: keep every ``every``-th sample of the traces along time.
        single: run by the per-run program (one run, ``indices[0]``) instead of the vmapped one.
    """

    indices: tuple[int, ...]
    overrides: dict | None = None
    seed: int | None = None
    every: int = 1
    single: bool = False


class ErrorSource(NamedTuple):
    """One error source of a system, for the error budget (:mod:`gnc_jax.budget`).

    Attributes:
        fields: the scenario fields (``"errors.delivery_position_km"``) of its magnitudes; a
            source whose fields are all zero draws nothing and is left out of a budget.
        draws: the draws it owns, each ``(path,)`` (the whole draw) or ``(path, lo, hi)`` (a
            slice of the draw's last axis); ``path``: the stream identifiers folded into the
            run's key, :data:`gnc_jax._random.INDEX` for an event index (image ``i``).
        doc: one line for the budget's tables.
    """

    fields: tuple[str, ...]
    draws: tuple[tuple, ...]
    doc: str = ""


class StepCost(NamedTuple):
    """The cost model of one system on one platform: a study of ``runs`` runs of ``steps``
    steps each on ``d`` devices takes ``ceil(runs / d) x steps x run_step_s + steps x
    step_latency_s`` seconds after compilation (:func:`gnc_jax.estimate_cost`).

    Attributes:
        run_step_s: throughput term, seconds per run and step on one device.
        step_latency_s: latency term, seconds per step of the strictly sequential loop,
            whatever the batch (a GPU's kernel launches and synchronisation; ~0 on a CPU).
        source: where the figures were measured.
    """

    run_step_s: float
    step_latency_s: float
    source: str


H100_SOURCE = "an H100 80GB (jax 0.11.2): benchmarks/gpu_acceptance_h100.json"
"""Where the packaged systems' GPU cost models were measured (``benchmarks/gpu_acceptance.py``,
the capsule's in ``benchmarks/backend_probe_h100.json``; re-measure with
``benchmarks/cost_calibration.py --device gpu``)."""
CPU_SOURCE = "the 2-core development machine, 2 host devices: benchmarks/cost_calibration.py --fit"
"""Where the packaged systems' CPU cost models with a latency term were fitted (a small and a
chunk-sized study of each example; re-measure with ``benchmarks/cost_calibration.py --fit``)."""
H100_LAYOUT_SOURCE = "an H100 80GB (jax 0.11.2): benchmarks/gpu_layout_h100.json"
"""Where a GPU cost model measured in a system's own accelerator layout was taken
(``benchmarks/gpu_loops.py --sweep`` and the CLI)."""


class AbstractSystem(abc.ABC):
    """Base class of every system (see the module docstring).

    Class attributes:
        name: the scenario ``kind`` that selects this system.
        description: one line for ``gnc-jax list --fields`` and the docs.
        sections: the schema of the scenario sections that no parameter Module declares.
        parameter_modules: Modules whose fields are declared with
            :func:`gnc_jax.params.param` (section, units, range, default): their fields are
            added to the schema (:func:`sections_with`).
        law_family: the guidance-law family base (``None`` when the system has no choice of
            law); its registered laws are the allowed values of ``guidance.law``.
        default_law: the law used when a scenario does not name one.
        tunable: scenario names of tunable leaves beyond the laws' own (which a law declares
            with ``param(..., tunable=True)``); all of them: :meth:`tunable_names`.
        metrics: summary keys that objectives and envelope maps may read.
        paper_labels: ``{summary key: label}`` for the paper-vs-gnc_jax tables.
        example: a packaged scenario name (or a TOML path) of this system.
        test_overrides: ``{"section.field": value}`` that make ``example`` cheap for tests.
        step_seconds: measured wall seconds of one step (:meth:`steps_per_run`) on one core,
            the CPU's cost model (no latency term; :meth:`step_cost`).
        step_costs: ``{platform: StepCost}`` of the other platforms, measured there with
            ``benchmarks/cost_calibration.py --device``; a platform without one has no cost
            estimate (:meth:`step_cost` is ``None``), never the CPU's figure.
        run_bytes: device memory one run of the example scenario needs in a compiled batch
            (the executable's temporary, argument and output bytes per run); the planner sizes
            a GPU's chunks with it, the memory guard checks the compiled figure.
        chunk_per_device: runs per host device in one compiled call of a study, measured
            where the per-run time is lowest (a batch whose working set outgrows the core's
            cache, or whose lock-step loops wait longer for the slowest run, is slower per
            run; too small a batch pays the per-operation overhead); ``None``: 1024 runs per
            call.
        rare_layout: a :class:`~gnc_jax._numerics.RareLayout`: when a study on the CPU runs
            the closed loop in the layout that computes rarely taken work only for the runs
            that take it (:attr:`~gnc_jax._numerics.LoopShape.rare`); ``None``: never.
        vector_lanes: a device batch of 64 runs or more is padded to a multiple of this
            (``montecarlo.padded_chunk``), measured per system: 8 where the loop is
            elementwise work that XLA vectorises (a batch off the SIMD width ran 1.6x slower
            per run), 1 (no padding) where lock-step waiting dominates.
        envelope_metrics: ``{summary key: label}`` mapped by ``gnc-jax envelope`` (one heat map
            each; ``failed_fraction`` is the fraction of failed runs).
        error_sources: ``{name: ErrorSource}``: every random draw of a run belongs to exactly
            one (the error budget routes them; a draw of none is an error there).
        source_groups: ``{group: (source, ...)}`` that a budget may take as one source.
        budget_metrics: ``{name: f(outcomes) -> array}`` that the budget decomposes
            (``outcomes`` maps outcome fields to arrays, numpy or traced).
        batch_tolerance: ``(rtol, atol)`` to which a vmapped batch reproduces the per-run
            program on float outcomes (integer outcomes must be equal): both compute the same
            run, but XLA compiles the two programs separately and may round differently.
        accelerator_loop_shape: the :class:`~gnc_jax._numerics.LoopShape` this system's loops
            take on a GPU, where it was measured to beat the accelerators' default; ``None``:
            the default.
        cpu_loop_shape: likewise on the CPU.
    """

    name: ClassVar[str]
    description: ClassVar[str] = ""
    sections: ClassVar[Schema] = {}
    parameter_modules: ClassVar[tuple[type, ...]] = ()
    law_family: ClassVar[type | None] = None
    default_law: ClassVar[str] = ""
    tunable: ClassVar[tuple[str, ...]] = ()
    metrics: ClassVar[tuple[str, ...]] = ()
    paper_labels: ClassVar[dict[str, str]] = {}
    example: ClassVar[str] = ""
    batch_tolerance: ClassVar[tuple[float, float]] = (1e-9, 1e-9)
    test_overrides: ClassVar[dict[str, Any]] = {}
    step_seconds: ClassVar[float] = 1e-6
    step_costs: ClassVar[dict[str, StepCost]] = {}
    run_bytes: ClassVar[int] = 16_000
    chunk_per_device: ClassVar[int | None] = None
    rare_layout: ClassVar[Any] = None
    vector_lanes: ClassVar[int] = 1
    envelope_metrics: ClassVar[dict[str, str]] = {"failed_fraction": "failed fraction"}
    error_sources: ClassVar[dict[str, ErrorSource]] = {}
    source_groups: ClassVar[dict[str, tuple[str, ...]]] = {}
    budget_metrics: ClassVar[dict[str, Any]] = {}
    accelerator_loop_shape: ClassVar[Any] = None
    cpu_loop_shape: ClassVar[Any] = None

    # ---- cost ----
    def steps_per_run(self, config: dict) -> float | None:
        """Simulation steps one run of a validated configuration takes (truth steps plus the
        predictor and corrector work, in truth-step equivalents); ``None`` when unknown.

        With ``step_seconds`` (wall seconds per step on one core of the development machine,
        measured by ``benchmarks/cost_calibration.py``) it gives the cost estimate that
        :func:`gnc_jax.run_study` checks before the reference design or compilation.
        """
        return None

    def step_cost(self, platform: str) -> StepCost | None:
        """The cost model on ``platform`` (``"cpu"``, ``"gpu"``); ``None``: not calibrated."""
        if platform in self.step_costs:
            return self.step_costs[platform]
        if platform == "cpu":
            return StepCost(self.step_seconds, 0.0, "one core of the development machine")
        return None

    # ---- scenario ----
    def laws(self) -> dict[str, type]:
        """``{name: law class}`` of the registered laws of this system's family."""
        return dict(self.law_family.laws) if self.law_family is not None else {}

    def tunable_names(self) -> tuple[str, ...]:
        """Scenario names of the tunable leaves: ``tunable`` plus every law parameter declared
        ``tunable=True`` (``guidance.<law>.<field>``), so a new law brings its own."""
        names = list(self.tunable)
        for law, cls in self.laws().items():
            for attribute, spec in declared_params(cls).items():
                if spec.tunable:
                    names.append(f"guidance.{law}.{file_name(attribute, spec)}")
        return tuple(dict.fromkeys(names))

    def law_name(self, raw: dict) -> str:
        """The law a (raw or validated) configuration flies."""
        guidance = raw.get("guidance", {})
        name = guidance.get("law", self.default_law) if isinstance(guidance, dict) else ""
        return name if isinstance(name, str) else ""

    def schema(self) -> Schema:
        """Every section, with ``guidance.law`` and one ``[guidance.<law>]`` table per law."""
        out = sections_with(self.sections, *self.parameter_modules)
        laws = self.laws()
        if laws:
            out.setdefault("guidance", {})
            out["guidance"] = {
                "law": Field(
                    "str",
                    self.default_law or next(iter(laws)),
                    choices=tuple(laws),
                    doc="guidance law; its gains are in [guidance.<law>]",
                ),
                **out["guidance"],
            }
            for name, cls in laws.items():
                out[f"guidance.{name}"] = schema_of(cls)
        return out

    def validate(self, raw: dict, where: str = "") -> dict:
        """Fill defaults and check ``raw`` (types, ranges, :meth:`check`, then the law's
        ``check``)."""
        laws = self.laws()
        chosen = self.law_name(raw)
        if laws and isinstance(raw.get("guidance"), dict) and "law" in raw["guidance"]:
            if chosen not in laws:  # before its [guidance.<law>] table is called unknown
                raise ScenarioError(
                    f"{where}guidance.law: got {raw['guidance']['law']!r}; allowed: one of "
                    + ", ".join(repr(n) for n in sorted(laws))
                    + f" (a law of your own: import its module first, or name it in {PLUGINS_ENV})"
                )
        optional = {f"guidance.{n}" for n in laws if n != chosen}
        config = validate(raw, self.schema(), where, optional)
        self.check(config)  # the system's domain first: the laws' checks may rely on it
        if laws:
            law = laws[config["guidance"]["law"]]
            law.check(config["guidance"][law.law_name], config)
        return config

    def check(self, config: dict) -> None:
        """Cross-field checks of a validated configuration (raise :class:`ScenarioError`)."""
        return None

    def linear_unavailable(self, config: dict) -> str | None:
        """Why the error budget's linear method (forward-mode derivatives about the nominal
        run) does not apply to a validated configuration, or None when it does. Default:
        None."""
        return None

    def warnings(self, config: dict) -> list[str]:
        """One-line warnings about a valid but doubtful configuration: the law's (its
        ``warnings``); printed by the CLI before a study and kept in ``summary.json``."""
        laws = self.laws()
        if not laws:
            return []
        law = laws[config["guidance"]["law"]]
        return list(law.warnings(config["guidance"][law.law_name], config))

    # ---- envelope (gnc_jax.operating_envelope) ----
    def envelope_check(self, configs: list[dict], **options) -> list[dict]:
        """Pre-check of the cells of an envelope, before anything is simulated: for each
        validated configuration ``{"feasible": bool, "reason": str, "columns": {...}}``
        (``columns``: extra columns of the cells table). Default: every cell feasible."""
        return [{"feasible": True} for _ in configs]

    def envelope_overlay(self, ax, envelope, x_key: str, y_key: str | None) -> None:
        """Draw what the system knows of the envelope's axes (e.g. physical limits) on a heat
        map ``ax`` whose axes are the grid fields ``x_key`` and ``y_key``. Default: nothing."""
        return None

    # ---- simulation ----
    def build_law(self, config: dict, ctx=None):
        """The guidance law a validated configuration flies (``None`` without a family)."""
        laws = self.laws()
        if not laws:
            return None
        cls = laws[config["guidance"]["law"]]
        return cls.from_config(config["guidance"][cls.law_name], config, ctx)

    @abc.abstractmethod
    def build(self, scenario) -> tuple[Any, Any]:
        """``(params, law)`` of a validated scenario, in SI units."""

    @abc.abstractmethod
    def simulate(self, params, law, key, record: bool = False):
        """One run: ``(outcome, trace)``; ``trace`` is ``None`` unless ``record``."""

    def reverse_mode(self, params, differentiated: Collection[str] | None = None):
        """``params`` set up to be differentiated in reverse mode (``jax.grad``): the same
        outcomes, from loops that reverse mode can cross with bounded memory (a system whose
        loops are ``lax.while_loop`` swaps them for checkpointed ones). ``differentiated``:
        the scenario names of the only parameters differentiated (``None``: anything may
        be), which lets a system leave out of the reverse pass what none of them reaches.
        Default: ``params`` (scans, each of whose steps the simulator checkpoints itself)."""
        del differentiated
        return params

    gradient_costs: ClassVar[tuple[float, float, float] | None] = None
    """``(a, b, r)``: a tuning gradient's cost measured on the system's own loop, in plain runs
    of the same batch on one device: forward mode ``a + b p`` for ``p`` parameters, the
    tuner's reverse mode ``r`` whatever their number; ``gradient="auto"`` takes the cheaper
    (:func:`~gnc_jax.tuning.optimisers.gradient_mode`). ``None``: reverse mode from
    :data:`~gnc_jax.tuning.optimisers.REVERSE_FROM` parameters on."""

    reverse_on_one_device: ClassVar[bool] = False
    """Whether reverse mode runs a batch on one device instead of sharding it: equinox's
    checkpointed ``while_loop`` cannot be differentiated inside ``shard_map`` (it checks its
    carry against an example without the mesh's sharding and refuses the loop)."""

    # ---- results ----
    def statistics(self, outcomes: dict, ok) -> dict[str, Any]:
        """Summary statistics over the ``ok`` runs (``{}`` when there are none)."""
        return {}

    def smooth_objective(self, outcomes):
        """A differentiable scalar of a batch of outcomes (a NamedTuple of arrays with the run
        on the first axis), for gradient checks and as the default tuning objective; ``None``
        when the system has none."""
        return None

    def figure_traces(self, summary: dict, runs: dict, scenario) -> dict[str, TraceRequest]:
        """The runs the figures draw, by name; the report layer simulates them and passes
        ``{name: (outcomes, traces)}`` to :meth:`figures`. Default: none."""
        return {}

    def figures(self, summary: dict, runs: dict, scenario, out, traces=None) -> list:
        """Write the report figures into the directory ``out``; return their paths.
        ``traces``: ``{name: (outcomes, traces)}`` of :meth:`figure_traces`, dicts of numpy
        arrays (run on the first axis unless the request was ``single``)."""
        return []

    def __repr__(self) -> str:
        return f"<system {self.name!r}>"


def sections_with(sections: Schema, *modules: type) -> Schema:
    """``sections`` plus the fields the parameter Modules ``modules`` declare, each in the
    section its declaration names (:func:`gnc_jax.params.param` with ``section=``)."""
    out = {name: dict(fields) for name, fields in sections.items()}
    for cls in modules:
        for attribute, spec in declared_params(cls).items():
            out.setdefault(spec.section, {})[file_name(attribute, spec)] = spec.field
    return out


def register_system(system):
    """Register a system (a subclass of :class:`AbstractSystem`, or an instance) under its
    ``name``; usable as a class decorator. Registering another object under a name that is
    taken is an error; registering the same class again replaces the instance."""
    instance = system() if isinstance(system, type) else system
    if not isinstance(instance, AbstractSystem):
        raise TypeError(f"{system!r} is not an AbstractSystem")
    name = instance.name
    old = _REGISTRY.get(name)
    if old is not None and type(old).__qualname__ != type(instance).__qualname__:
        raise ValueError(f"a system named {name!r} is already registered ({old!r})")
    _REGISTRY[name] = instance
    return system


PLUGINS_ENV = "GNC_JAX_PLUGINS"
"""Environment variable: comma-separated modules to import before the registry is read (a
user's systems, laws and measurements register themselves on import); installed packages can
instead declare entry points in the group ``gnc_jax.plugins``."""

_loaded = False


def _load_plugins() -> None:
    """Import the user's plugins once (the built-in systems register when ``gnc_jax.systems``
    is imported)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for entry in importlib.metadata.entry_points(group="gnc_jax.plugins"):
        entry.load()
    for name in filter(None, os.environ.get(PLUGINS_ENV, "").split(",")):
        try:
            importlib.import_module(name.strip())
        except ImportError as e:
            raise ScenarioError(
                f"{PLUGINS_ENV}: cannot import {name.strip()!r} ({e}); allowed: importable "
                "module names separated by commas"
            ) from None


def get_system(name: str) -> AbstractSystem:
    """The registered system of scenario kind ``name``."""
    _load_plugins()
    if name not in _REGISTRY:
        renamed = f" (renamed {_RENAMED[name]!r})" if name in _RENAMED else ""
        raise ScenarioError(
            f"scenario.kind: {name!r}{renamed}; allowed: one of {', '.join(_REGISTRY)}"
        )
    return _REGISTRY[name]


def systems() -> dict[str, AbstractSystem]:
    """Every registered system by name."""
    _load_plugins()
    return dict(_REGISTRY)


def law_parameters(law_cls) -> dict[str, str]:
    """``{attribute: file name}`` of a law's declared parameters."""
    return {a: file_name(a, s) for a, s in declared_params(law_cls).items()}


def tunable_leaf(system: AbstractSystem, name: str):
    """``(where, attribute)`` of a tunable scenario name: ``("law", "k1")`` for
    ``guidance.<law>.k1``. Only law gains are tunable leaves so far."""
    parts = name.split(".")
    if len(parts) == 3 and parts[0] == "guidance":
        cls = system.laws().get(parts[1])
        if cls is not None:
            for attribute, file in law_parameters(cls).items():
                if file == parts[2]:
                    return "law", attribute
    raise ScenarioError(
        f"{name}: not a tunable leaf of {system.name}; allowed: {', '.join(system.tunable_names())}"
    )


__all__ = [
    "AbstractSystem",
    "ErrorSource",
    "register_system",
    "get_system",
    "systems",
    "tunable_leaf",
    "sections_with",
]
