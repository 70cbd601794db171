"""Gradient-based tuning of guidance gains: ``gj.tune``, ``gnc-jax tune``.

The gains to tune are chosen by their scenario names (``guidance.los.k1``, ``guidance.apn.n0``,
``guidance.skip_entry.k_range``, ...: :meth:`~gnc_jax.systems.AbstractSystem.tunable_names`).
An objective over a batch of dispersed runs is minimised with optax (Adam on a cosine-decayed
step, gradient clipping) through the laws' smooth relaxations, at the scenario's own relaxation
temperature T (``temperature=(start, end)`` anneals geometrically); every eighth of the steps
the hard logic is checked on training runs, and the result is the checked point (or the start)
where the hard objective is lowest. The result is evaluated with the hard logic (the normal
simulate path) on held-out runs, paired: initial and tuned gains fly the same held-out runs,
and the table gives a bootstrap confidence interval of the paired difference.

**Why no annealing by default.** A relaxation is only useful where it orders gains as the
hard logic does. Measured on 256 deep-impact-los runs, miss RMS + 10 s x Δv mean, hard logic
against the relaxed switch at T = 0.2 / 0.05 / 0.0125 / 0.003: (4, 1) 138.1 against 226.0 /
125.4 / 134.5 / 137.1; (3, 1) 125.7 against 232.0 / 118.8 / 123.6 / 125.0; (5.54, 0.88) 158.8
against 221.3 / 143.6 / 156.3 / 158.2. At 4 T the relaxed switch ranks (5.54, 0.88) best and
(3, 1) worst, the reverse of the hard logic: annealing from 4 T to T ended at gains 15 % worse
on held-out runs. Annealing from T to T / 4 went towards (3.4, 1.15) while T was high and
drifted back to (4.06, 1.48) as it fell (the pathwise gradient of a colder switch is rougher);
at the constant T = 0.05 the same tuning reached (1.85, 1.05), 16 % better on held-out runs.

**Run indices.** Run ``i`` uses ``fold_in(key(seed), i)`` as in every study. Training step
``s`` flies runs ``(s * batch + j) mod train_runs`` (default ``train_runs = batch * steps``: a
fresh batch each step); held-out runs are ``HELDOUT_OFFSET + j``, and ``train_runs <=
HELDOUT_OFFSET`` is enforced, so the two sets never share a run.

**Constraints by reparametrisation.** The optimiser moves ``theta`` (one number per gain,
unconstrained): a gain with a lower bound ``lo`` is ``lo + exp(theta)`` (a log scale, so Adam's
steps are relative changes); a pair the law needs ordered (``ordered_gains`` of the law class:
k1 >= k2, trigger_on > trigger_off) is ``smaller = lo + exp(theta_s)``, ``larger = smaller +
exp(theta_l)``; upper bounds clip.

**Forward mode, chosen by measurement.** The gradient is ``jax.jacfwd`` (one forward tangent
per gain, vectorised) by default; ``gradient="reverse"`` is ``jax.grad``. Measured with
``benchmarks/tune_gradient.py`` (one core of the shared 2-core machine, full paper scenarios,
the relaxed objective; value / forward / reverse, compiled temp memory):

* deep-impact-los, 16 runs, 2 gains: 0.11 s / 0.23 s (2.1x) / 4.3 s (39x); temp memory
  0 / 0.1 MB / 273 MB; compile 15 / 32 / 155 s;
* bennu-apn, 8 runs, 4 gains: 0.81 s / 14.3 s (18x) / 15.1 s (19x); 0 / 0.1 MB / 2.8 GB;
  compile 19 / 40 / 84 s (one gain, forward: 9.5 s against 1.14 s, 8x).

Reverse mode keeps the residuals of every step of the closed loop (17 MB per LOS run over
7200 steps, 350 MB per intercept run over 91 800 steps with an EKF update each): 256 intercept
runs would need 90 GB. A ``jax.checkpoint`` of the whole run does not bound the residuals of
the scans inside it, and checkpointing the simulators' own scans would change every simulator;
the capsule's flight (a ``while_loop``) is not reverse-differentiable at all. Forward mode needs
no memory beyond the forward run whatever the loop's length, and with the few gains a law has
it is also the faster (LOS: 19x faster than reverse; intercept: equal). Its cost per gain
depends on the loop: 0.6 of a run per gain for the LOS law (the EKF runs once per 15 s image),
but 4 to 7 runs per gain for the intercept, whose EKF update at every 1 s step differentiates
its matrix algebra once per tangent.

**Gradient-free baseline** (``method="es"``): an antithetic evolution strategy in the same
``theta`` with the same optimiser, evaluated with the hard logic; each generation flies
``2 x population`` members on ``batch // (2 x population)`` common runs, so it simulates the
same number of runs per step as the gradient tuner (the same budget in runs). ``eval_every``
records the held-out objective along the way (:meth:`TuneResult.runs_to_reach`).
"""

import dataclasses
import functools
import json
import math
import pathlib
import re
import time
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ._status import Status
from .montecarlo import batch_function, build
from .params import declared_params
from .scenario import Scenario, ScenarioError, load_scenario
from .systems.base import AbstractSystem, tunable_leaf

HELDOUT_OFFSET = 2**30
"""First run index of the held-out set; training indices stay below it."""


# ---- objectives ----


def _wmean(x, w):
    return jnp.sum(jnp.where(w > 0, x, 0.0) * w) / jnp.maximum(jnp.sum(w), 1.0)


def _miss_rms(out, w, arg, t):
    return jnp.sqrt(_wmean(out.miss_m**2, w))


def _dv_mean(out, w, arg, t):
    return _wmean(out.dv_mps, w)


def _chute_rms(out, w, arg, t):
    return jnp.sqrt(_wmean(out.downrange_err_km**2 + out.crossrange_err_km**2, w))


def _impact_distance(out):
    # the B-plane point relative to the target's centre where the outcome has it (impactor:
    # the miss is from the aim point), else the miss itself (intercept: aimed at the centre)
    if hasattr(out, "b_t_m"):
        return jnp.sqrt(out.b_t_m**2 + out.b_r_m**2)
    return out.miss_m


def _hit_probability(out, w, radius, t):
    """1 - P(hit): the fraction of runs whose impact point lies outside ``radius``; smooth: a
    logistic of width ``t x radius``."""
    d = _impact_distance(out)
    if t is None:
        return 1.0 - _wmean((d <= radius).astype(float), w)
    return 1.0 - _wmean(jax.nn.sigmoid((radius - d) / (t * radius)), w)


def _peak_load(out, w, limit, t):
    """Mean excess of the peak load over ``limit`` (g); smooth: a softplus of width t x limit."""
    excess = out.load_peak_g - limit
    if t is None:
        return _wmean(jnp.maximum(excess, 0.0), w)
    width = t * limit
    return _wmean(width * jax.nn.softplus(excess / width), w)


@dataclasses.dataclass(frozen=True)
class ObjectiveTerm:
    """A built-in objective term: ``fn(outcomes, weights, arg, temperature)`` (temperature
    ``None``: the hard value), the outcome fields it reads, and what its argument means."""

    fn: Callable
    fields: tuple[str, ...]
    doc: str
    arg: str = ""  # meaning of the argument in name(arg); "" = none


TERMS: dict[str, ObjectiveTerm] = {
    "miss_rms": ObjectiveTerm(_miss_rms, ("miss_m",), "RMS of the miss, m"),
    "dv_mean": ObjectiveTerm(_dv_mean, ("dv_mps",), "mean Δv, m/s"),
    "hit_probability": ObjectiveTerm(
        _hit_probability,
        ("miss_m",),
        "1 - P(impact within the target's radius)",
        arg="target radius in m (default: the scenario's target size)",
    ),
    "chute_rms": ObjectiveTerm(
        _chute_rms,
        ("downrange_err_km", "crossrange_err_km"),
        "RMS of the chute-deploy error, km",
    ),
    "peak_load": ObjectiveTerm(
        _peak_load, ("load_peak_g",), "mean excess of the peak load over a limit, g", "limit in g"
    ),
}
"""Built-in objective terms by name: a weighted sum of them is written ``"miss_rms+10*dv_mean"``
(``peak_load(8)``, ``hit_probability(300)`` take an argument)."""

_TERM_RE = re.compile(r"^\s*(?:([0-9.eE+-]+)\s*\*\s*)?([a-z_]+)\s*(?:\(\s*([^)]*)\s*\))?\s*$")


def _allowed_objectives() -> str:
    return (
        ", ".join(f"{n}({t.arg.split(' ')[0]})" if t.arg else n for n, t in TERMS.items())
        + ", weighted sums such as 'miss_rms+10*dv_mean', or a callable(outcomes, weights)"
    )


def _target_radius_m(scenario: Scenario) -> float | None:
    target = scenario.config.get("target", {})
    if "target_radius_m" in target:
        return float(target["target_radius_m"])
    if "semi_axes_km" in target:
        return 1e3 * float(min(target["semi_axes_km"]))
    return None


@dataclasses.dataclass(frozen=True)
class Objective:
    """A tuning objective: a weighted sum of built-in terms, or a user callable.

    ``value(outcomes, weights, temperature)`` is the smooth objective at ``temperature`` and the
    hard one for ``temperature=None``; ``weights`` is 1 for the runs that count (status ``ok``)
    and 0 for the others. A user callable ``fn(outcomes, weights)`` is used for both.
    """

    spec: str
    terms: tuple[tuple[float, str, float | None], ...] = ()  # (weight, name, argument)
    fn: Callable | None = None

    @property
    def structure(self):
        """What compiled code depends on: the terms and their arguments, not their weights
        (an argument of the compiled functions: a sweep over weights compiles once)."""
        return tuple((name, arg) for _, name, arg in self.terms), self.fn

    @property
    def weights(self):
        return jnp.asarray([w for w, _, _ in self.terms], dtype=jnp.float64)

    def value(self, outcomes, weights, temperature=None, term_weights=None):
        if self.fn is not None:
            return self.fn(outcomes, weights)
        term_weights = self.weights if term_weights is None else term_weights
        return sum(
            term_weights[i] * TERMS[name].fn(outcomes, weights, arg, temperature)
            for i, (_, name, arg) in enumerate(self.terms)
        )

    def term_values(self, outcomes, weights) -> dict[str, float]:
        """The hard value of each term (for the held-out table)."""
        return {
            _term_label(name, arg): float(TERMS[name].fn(outcomes, weights, arg, None))
            for _, name, arg in self.terms
        }

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(f for _, name, _ in self.terms for f in TERMS[name].fields)


def _term_label(name, arg):
    return name if arg is None else f"{name}({arg:g})"


def parse_objective(objective, scenario: Scenario) -> Objective:
    """An :class:`Objective` from a spec string (``"miss_rms+10*dv_mean"``), a mapping
    ``{term: weight}``, a callable ``fn(outcomes, weights)``, or ``None`` (the system's
    ``smooth_objective``, hard and smooth alike). Raises :class:`ScenarioError` naming the bad
    term."""
    if callable(objective):
        return Objective(getattr(objective, "__name__", "callable"), fn=objective)
    if objective is None:
        system = scenario.system
        if type(system).smooth_objective is AbstractSystem.smooth_objective:
            raise ScenarioError(
                f"objective: none given and {system.name} has no smooth_objective; allowed: "
                f"{_allowed_objectives()}"
            )
        return Objective(
            f"{system.name}.smooth_objective", fn=lambda out, w: system.smooth_objective(out)
        )
    if isinstance(objective, dict):
        objective = "+".join(f"{w!r}*{n}" for n, w in objective.items())
    if not isinstance(objective, str) or not objective.strip():
        raise ScenarioError(f"objective: {objective!r}; allowed: {_allowed_objectives()}")
    terms = []
    for part in objective.split("+"):
        m = _TERM_RE.match(part)
        name = m.group(2) if m else part.strip()
        if m is None or name not in TERMS:
            raise ScenarioError(
                f"objective: {part.strip()!r} in {objective!r}; allowed: {_allowed_objectives()}"
            )
        try:
            weight = float(m.group(1)) if m.group(1) else 1.0
            arg = float(m.group(3)) if m.group(3) else None
        except ValueError:
            raise ScenarioError(
                f"objective: {part.strip()!r}: not a number; allowed: {_allowed_objectives()}"
            ) from None
        term = TERMS[name]
        if name == "hit_probability" and arg is None:
            arg = _target_radius_m(scenario)
            if arg is None:
                raise ScenarioError(
                    f"objective: hit_probability: scenario {scenario.name} has no target size;"
                    " allowed: hit_probability(RADIUS_M)"
                )
        if term.arg and arg is None:
            raise ScenarioError(f"objective: {name} needs an argument; allowed: {name}({term.arg})")
        if not term.arg and arg is not None:
            raise ScenarioError(f"objective: {name} takes no argument; allowed: {name}")
        terms.append((weight, name, arg))
    return Objective(objective.replace(" ", ""), tuple(terms))


def _check_fields(objective: Objective, outcome_fields: Sequence[str], kind: str) -> None:
    for f in objective.fields:
        if f not in outcome_fields:
            name = next(n for _, n, _ in objective.terms if f in TERMS[n].fields)
            usable = [n for n, t in TERMS.items() if all(x in outcome_fields for x in t.fields)]
            raise ScenarioError(
                f"objective: {name} needs the outcome {f!r}, which a {kind} run does not have;"
                f" allowed for {kind}: {', '.join(usable)}"
            )


# ---- gains and their reparametrisation ----


@dataclasses.dataclass(frozen=True)
class Gain:
    """A tunable leaf: its scenario name, the law attribute, the factor from the file's units
    to the law's SI leaf, and its allowed range (file units)."""

    name: str
    attribute: str
    si_per_file: float
    lo: float | None
    hi: float | None


def resolve_gains(scenario: Scenario, names) -> list[Gain]:
    """The :class:`Gain` of each scenario name; :class:`ScenarioError` (one line naming the
    field and the allowed names) for an unknown or non-tunable name, or a gain of a law the
    scenario does not fly. Nothing is built."""
    system = scenario.system
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    law_name = system.law_name(scenario.config)
    own = [n for n in system.tunable_names() if n.startswith(f"guidance.{law_name}.")]
    if not names:
        raise ScenarioError(f"params: none given; allowed: {', '.join(own)}")
    gains = []
    for name in names:
        where, attribute = tunable_leaf(system, name)
        if name not in system.tunable_names():
            raise ScenarioError(
                f"{name}: not a tunable leaf of {system.name}; allowed: "
                f"{', '.join(system.tunable_names())}"
            )
        if not name.startswith(f"guidance.{law_name}."):
            raise ScenarioError(
                f"{name}: a gain of a law this scenario does not fly (guidance.law = "
                f"{law_name!r}); allowed: {', '.join(own)}"
            )
        spec = declared_params(system.laws()[law_name])[attribute]
        lo = spec.field.lo
        value = float(scenario[name])
        if lo is not None and value <= lo:
            raise ScenarioError(
                f"{name}: {value:g} is at its lower bound {lo:g}, where the log "
                f"reparametrisation cannot start; allowed: a start value > {lo:g} (--set)"
            )
        gains.append(Gain(name, attribute, float("nan"), lo, spec.field.hi))
    if len(set(names)) != len(names):
        raise ScenarioError(f"params: {','.join(names)} names a gain twice; allowed: each once")
    return gains


@dataclasses.dataclass(frozen=True)
class Reparametrisation:
    """``theta`` (unconstrained) <-> gains in file units (see the module docstring)."""

    lo: tuple  # lower bound of each gain (file units; -inf: none)
    hi: tuple
    below: tuple  # index of the gain each one must stay above (ordered pairs), -1: none
    above_fixed: tuple  # a fixed value the gain must stay above (file units), or None
    below_fixed: tuple  # a fixed value the gain must stay below, or None

    @staticmethod
    def of(scenario: Scenario, gains: list[Gain]) -> "Reparametrisation":
        system = scenario.system
        law_name = system.law_name(scenario.config)
        law_cls = system.laws()[law_name]
        files = [g.name.split(".")[-1] for g in gains]
        below = [-1] * len(gains)
        above_fixed: list = [None] * len(gains)
        below_fixed: list = [None] * len(gains)
        for larger, smaller in law_cls.ordered_gains:
            a = files.index(larger) if larger in files else None
            b = files.index(smaller) if smaller in files else None
            if a is not None and b is not None:
                below[a] = b
            elif a is not None:
                above_fixed[a] = float(scenario[f"guidance.{law_name}.{smaller}"])
            elif b is not None:
                below_fixed[b] = float(scenario[f"guidance.{law_name}.{larger}"])
        lo = tuple(-math.inf if g.lo is None else g.lo for g in gains)
        hi = tuple(math.inf if g.hi is None else g.hi for g in gains)
        return Reparametrisation(lo, hi, tuple(below), tuple(above_fixed), tuple(below_fixed))

    def _order(self):
        # gains that sit above another come after it
        done, order = set(), []
        while len(order) < len(self.lo):
            for i in range(len(self.lo)):
                if i not in done and (self.below[i] < 0 or self.below[i] in done):
                    done.add(i)
                    order.append(i)
        return order

    def gains(self, theta):
        """Gains (file units) of ``theta``."""
        out = [None] * len(self.lo)
        for i in self._order():
            if self.below[i] >= 0:
                v = out[self.below[i]] + jnp.exp(theta[i])
            elif self.above_fixed[i] is not None:
                v = self.above_fixed[i] + jnp.exp(theta[i])
            elif self.below_fixed[i] is not None:
                base = max(self.lo[i], 0.0) if math.isfinite(self.lo[i]) else 0.0
                v = base + (self.below_fixed[i] - base) * jax.nn.sigmoid(theta[i])
            elif math.isfinite(self.lo[i]):
                v = self.lo[i] + jnp.exp(theta[i])
            else:
                v = theta[i]
            out[i] = jnp.minimum(v, self.hi[i]) if math.isfinite(self.hi[i]) else v
        return jnp.stack(out)

    def theta(self, gains) -> np.ndarray:
        """``theta`` of gains (file units): the inverse of :meth:`gains`."""
        g = np.asarray(gains, float)
        th = np.zeros(len(g))
        for i in range(len(g)):
            if self.below[i] >= 0:
                th[i] = np.log(g[i] - g[self.below[i]])
            elif self.above_fixed[i] is not None:
                th[i] = np.log(g[i] - self.above_fixed[i])
            elif self.below_fixed[i] is not None:
                base = max(self.lo[i], 0.0) if math.isfinite(self.lo[i]) else 0.0
                p = (g[i] - base) / (self.below_fixed[i] - base)
                th[i] = np.log(p / (1.0 - p))
            elif math.isfinite(self.lo[i]):
                th[i] = np.log(g[i] - self.lo[i])
            else:
                th[i] = g[i]
        if not np.all(np.isfinite(th)):
            raise ScenarioError(
                f"params: start values {list(g)} violate the law's order or bounds; allowed: "
                "values inside the law's constraints"
            )
        return th


# ---- the tuning problem ----


def _si_factors(scenario: Scenario, gains: list[Gain], law) -> list[float]:
    """SI leaf / file value of each gain (all conversions of tunable gains are linear)."""
    out = []
    for g in gains:
        file_value = float(scenario[g.name])
        si = float(getattr(law, g.attribute))
        out.append(si / file_value)
    return out


@functools.lru_cache(maxsize=16)
def _batch_function(system):
    return batch_function(system)


class _Problem:
    """What one tuning needs, built once: the built scenario (``sim``, ``law``), the gains <->
    law map and the objective. Its jitted functions take ``sim`` and ``law`` as arguments and
    are cached on the problem's static structure (:meth:`jitted`), so a second tuning of the
    same structure (another seed, other weights, other start values) does not recompile."""

    def __init__(self, scenario, gains, objective, seed):
        self.scenario, self.system, self.seed = scenario, scenario.system, seed
        self.sim, self.law = build(scenario)
        self.gains = tuple(
            dataclasses.replace(g, si_per_file=f)
            for g, f in zip(gains, _si_factors(scenario, gains, self.law), strict=True)
        )
        self.param = Reparametrisation.of(scenario, gains)
        self.objective = objective
        if objective.fn is None:  # traced, not compiled: bad input stops before compilation
            outcome = jax.eval_shape(
                lambda: self.system.simulate(self.sim, self.law, jax.random.key(0))[0]
            )
            _check_fields(objective, outcome._fields, self.system.name)
        self.fn, self.n_dev = _batch_function(self.system)
        self.seed_arr = jnp.asarray(seed, dtype=jnp.uint32)
        self.term_weights = objective.weights
        spec = declared_params(type(self.law)).get("temperature")
        self.law_temperature = (
            float(self.law.temperature) if spec is not None and not spec.static else None
        )

    @property
    def args(self):
        """The dynamic arguments of every jitted function: built scenario, law, seed, weights."""
        return self.sim, self.law, self.seed_arr, self.term_weights

    def jitted(self, kind: str, build_fn):
        key = (kind, self.system, self.objective.structure, self.param, self.gains, self.n_dev)
        if key not in _JITTED:
            if len(_JITTED) >= 32:
                _JITTED.pop(next(iter(_JITTED)))
            _JITTED[key] = jax.jit(build_fn())
        return _JITTED[key]

    def compiled(self, kind: str, build_fn, *args):
        """``(executable, compile_s)``: :meth:`jitted` compiled ahead of time for ``args``
        (reused for arguments of the same structure, shapes and dtypes; 0 s then)."""
        leaves, treedef = jax.tree_util.tree_flatten(args)
        shapes = tuple((jnp.shape(x), jnp.result_type(x)) for x in leaves)
        key = (kind, self.system, self.objective.structure, self.param, self.gains, treedef, shapes)
        if key in _COMPILED:
            return _COMPILED[key], 0.0
        t0 = time.perf_counter()
        executable = self.jitted(kind, build_fn).lower(*args).compile()
        if len(_COMPILED) >= 32:
            _COMPILED.pop(next(iter(_COMPILED)))
        _COMPILED[key] = executable
        return executable, time.perf_counter() - t0

    def law_at(self, law, gains_file):
        values = tuple(
            jnp.asarray(gains_file[i] * g.si_per_file, dtype=jnp.float64)
            for i, g in enumerate(self.gains)
        )
        return eqx.tree_at(
            lambda l: tuple(getattr(l, g.attribute) for g in self.gains), law, values
        )

    def padded(self, indices, size: int | None = None):
        """Indices padded to ``size`` (default: a whole number per device) by repeating them,
        and the weights of the real ones (1) and the padding (0)."""
        indices = np.asarray(indices, dtype=np.int64)
        n = -(-max(size or 0, len(indices)) // self.n_dev) * self.n_dev
        valid = np.arange(n) < len(indices)
        return jnp.asarray(np.resize(indices, n), dtype=jnp.int32), jnp.asarray(valid, float)

    @staticmethod
    def weights(outcomes, valid):
        # as run_study: a run with a non-finite float outcome is a failed (``nan``) run
        ok = outcomes.status == Status.ok
        finite = jnp.ones_like(valid, dtype=bool)
        for x in outcomes:
            if jnp.issubdtype(x.dtype, jnp.floating):
                finite &= jnp.isfinite(x).reshape(x.shape[0], -1).all(axis=1)
        return jnp.where(ok & finite, valid, 0.0)

    def smooth(self, args, theta, temperature, indices, valid):
        """The relaxed objective at ``theta`` on runs ``indices`` (pure in its arguments)."""
        sim, law, seed, term_weights = args
        law = law.relax(temperature) if temperature is not None else law.relax()
        out = self.fn(sim, self.law_at(law, self.param.gains(theta)), seed, indices)
        return self.objective.value(out, self.weights(out, valid), temperature, term_weights)

    def hard(self, args, gains_file, indices, valid):
        """``(objective, outcomes)`` of the hard logic with gains ``gains_file``."""
        sim, law, seed, term_weights = args
        out = self.fn(sim, self.law_at(law, gains_file), seed, indices)
        value = self.objective.value(out, self.weights(out, valid), None, term_weights)
        return value, out

    def hard_outcomes(self, gains_file, indices):
        fn = self.jitted("hard", lambda: self.hard)
        return fn(self.args, jnp.asarray(gains_file), indices, jnp.ones(len(indices)))[1]


_JITTED: dict = {}
_COMPILED: dict = {}


def train_indices(step: int, batch: int, train_runs: int) -> np.ndarray:
    """Run indices of training step ``step``: ``(step * batch + j) mod train_runs``."""
    return (step * batch + np.arange(batch)) % train_runs


def heldout_indices(runs: int) -> np.ndarray:
    """Run indices of the held-out set: ``HELDOUT_OFFSET + j``."""
    return HELDOUT_OFFSET + np.arange(runs, dtype=np.int64)


# ---- held-out evaluation ----


def paired_interval(stat_a, stat_b, n, confidence=0.95, resamples=1000, seed=0):
    """``(difference, lo, hi)`` of ``stat_b - stat_a`` over ``n`` paired runs: the difference on
    all runs and its percentile-bootstrap confidence interval, each resample drawing the same
    runs for both sides (``stat_x(indices)`` evaluates a statistic on a subset of the runs)."""
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, n, size=(resamples, n))
    diffs = np.array([stat_b(d) - stat_a(d) for d in draws])
    q = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(diffs, [q, 1.0 - q])
    every = np.arange(n)
    return float(stat_b(every) - stat_a(every)), float(lo), float(hi)


def evaluate_heldout(
    problem: _Problem,
    initial,
    tuned,
    runs: int,
    chunk: int | None = None,
    confidence: float = 0.95,
) -> dict[str, Any]:
    """Initial vs tuned gains (file units) on the same ``runs`` held-out runs, hard logic.

    Rows: the objective and each of its terms, with the paired difference (tuned - initial)
    and its bootstrap confidence interval over the runs that end ``ok`` with both gains.
    """
    indices = heldout_indices(runs)
    chunk = min(chunk or (problem.system.chunk_per_device or 512) * problem.n_dev, runs)
    sides = {}
    for side, gains in (("initial", initial), ("tuned", tuned)):
        parts = []
        for start in range(0, runs, chunk):
            real = indices[start : start + chunk]
            idx, _ = problem.padded(real, size=chunk)  # one compiled shape
            out = problem.hard_outcomes(np.asarray(gains), idx)
            n = len(real)
            parts.append(jax.tree_util.tree_map(lambda x, n=n: np.asarray(x)[:n], out))
        sides[side] = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)
    w = {s: np.asarray(problem.weights(o, jnp.ones(runs))) for s, o in sides.items()}
    both = np.flatnonzero((w["initial"] > 0) & (w["tuned"] > 0))
    objective = problem.objective

    def statistic(outcomes, name):
        paired = jax.tree_util.tree_map(lambda x: x[both], outcomes)

        def stat(i):
            sub = jax.tree_util.tree_map(lambda x: x[i], paired)
            if name == "objective":
                return float(objective.value(sub, jnp.ones(len(i)), None))
            return objective.term_values(sub, jnp.ones(len(i)))[name]

        return stat

    names = ["objective"]
    if objective.fn is None and len(objective.terms) > 1:
        names += [_term_label(n, arg) for _, n, arg in objective.terms]
    rows = []
    for name in names:
        a, b = statistic(sides["initial"], name), statistic(sides["tuned"], name)
        every = np.arange(len(both))
        ini, tun = a(every), b(every)
        diff, lo, hi = paired_interval(a, b, len(both), confidence)
        rows.append(
            dict(
                metric=name,
                initial=ini,
                tuned=tun,
                difference=diff,
                ci_low=lo,
                ci_high=hi,
                relative=diff / abs(ini) if ini else float("nan"),
            )
        )
    return dict(
        runs=runs,
        paired_runs=len(both),
        failed={s: int(runs - (w[s] > 0).sum()) for s in sides},
        confidence=confidence,
        first_index=int(indices[0]),
        rows=rows,
        outcomes=sides,
    )


def heldout_table(heldout: dict) -> str:
    """The held-out table as text."""
    pct = round(100 * heldout["confidence"])
    lines = [
        f"held-out: {heldout['paired_runs']} paired runs (indices from {heldout['first_index']}),"
        f" hard logic; failed initial {heldout['failed']['initial']}, tuned "
        f"{heldout['failed']['tuned']}",
        f"  {'metric':<22} {'initial':>12} {'tuned':>12} {'tuned-initial':>14} "
        f"{f'{pct} % CI':>26} {'change':>8}",
    ]
    for r in heldout["rows"]:
        ci = f"[{r['ci_low']:.4g}, {r['ci_high']:.4g}]"
        lines.append(
            f"  {r['metric']:<22} {r['initial']:>12.5g} {r['tuned']:>12.5g} "
            f"{r['difference']:>14.4g} {ci:>26} "
            f"{100 * r['relative']:>7.2f}%"
        )
    return "\n".join(lines)


# ---- the result ----


@dataclasses.dataclass
class TuneResult:
    """What :func:`tune` returns.

    Attributes:
        scenario: the scenario as given; tuned_scenario: the same with the tuned gains.
        names: the tuned gains' scenario names; initial, tuned: their values (file units).
        objective: the objective's spec; method: ``"adam"`` or ``"es"``.
        history: one dict per step: ``step``, ``objective`` (training batch; smooth for adam,
            hard for es), ``gains``, ``temperature``, ``runs`` (simulated so far), ``wall_s``
            (after compilation, evaluations excluded), and ``heldout`` where evaluated.
        heldout: the paired held-out evaluation (:func:`evaluate_heldout`), or ``None``.
        training_check: the hard objective on the first ``runs`` training runs of the start
            (``initial``), the last step (``last``) and the result (``tuned``, at
            ``selected_step``; -1: the start): a relaxation that misled the tuner shows there,
            without looking at the held-out runs (``None`` when ``check_runs=0``).
        compile_s, wall_s: compilation and training wall time.
    """

    scenario: Scenario
    tuned_scenario: Scenario
    names: list[str]
    initial: list[float]
    tuned: list[float]
    objective: str
    method: str
    seed: int
    batch: int
    steps: int
    history: list[dict]
    heldout: dict | None
    compile_s: float
    wall_s: float
    training_check: dict | None = None

    @property
    def tuned_gains(self) -> dict[str, float]:
        return dict(zip(self.names, self.tuned, strict=True))

    def runs_to_reach(self, target: float):
        """``(runs, wall_s)`` at the first held-out evaluation whose objective is at most
        ``target`` (``None`` if none reached it)."""
        for h in self.history:
            if h.get("heldout") is not None and h["heldout"] <= target:
                return h["runs"], h["wall_s"]
        return None

    def table(self) -> str:
        lines = []
        c = self.training_check
        if c:
            at = "the start" if c["selected_step"] < 0 else f"step {c['selected_step']}"
            lines.append(
                f"training runs 0..{c['runs'] - 1}, hard logic: start {c['initial']:.5g}, last "
                f"step {c['last']:.5g}, result ({at}) {c['tuned']:.5g}"
            )
        lines.append(heldout_table(self.heldout) if self.heldout else "(no held-out evaluation)")
        return "\n".join(lines)

    def summary(self) -> dict[str, Any]:
        out = {
            k: getattr(self, k)
            for k in ("names", "initial", "tuned", "objective", "method", "seed", "batch")
        }
        out.update(steps=self.steps, compile_s=self.compile_s, wall_s=self.wall_s)
        out["training_check"] = self.training_check
        if self.heldout:
            out["heldout"] = {k: v for k, v in self.heldout.items() if k != "outcomes"}
        return out

    def save(self, out_dir) -> dict[str, str]:
        """Write ``tuned.toml`` (runnable with ``gnc-jax run``), ``training.json`` (history),
        ``heldout.json`` and ``training.png`` into ``out_dir``."""
        out = pathlib.Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {
            "tuned": out / "tuned.toml",
            "training": out / "training.json",
            "heldout": out / "heldout.json",
            "figure": out / "training.png",
        }
        paths["tuned"].write_text(self.tuned_scenario.to_toml())
        paths["training"].write_text(json.dumps(self.history, indent=1))
        paths["heldout"].write_text(json.dumps(self.summary(), indent=1))
        plot_training(self, paths["figure"])
        return {k: str(v) for k, v in paths.items()}


def plot_training(result: TuneResult, path) -> None:
    """``training.png``: the objective and each gain per step."""
    from .plotting import pyplot

    plt = pyplot()
    steps = [h["step"] for h in result.history]  # the gains and objective before its update
    n = len(result.names)
    fig, axes = plt.subplots(n + 1, 1, figsize=(6.4, 2.0 * (n + 1)), sharex=True)
    axes[0].plot(steps, [h["objective"] for h in result.history], label="training batch")
    relaxed = any(h.get("temperature") is not None for h in result.history)
    label = "training batch" + (
        " (relaxed)" if relaxed else " (hard)" if result.method == "es" else ""
    )
    axes[0].lines[0].set_label(label)
    # a check after step s's update is of the gains plotted at s + 1
    checks = [(h["step"] + 1, h["check"]) for h in result.history if h.get("check") is not None]
    if result.training_check:
        checks.insert(0, (0, result.training_check["initial"]))
    if checks:
        axes[0].plot(*zip(*checks, strict=True), "s", label="hard check, training runs")
    ev = [(h["step"], h["heldout"]) for h in result.history if h.get("heldout") is not None]
    if ev:
        axes[0].plot(*zip(*ev, strict=True), "o-", label="held-out (hard)")
    axes[0].legend(fontsize=8)
    selected = (result.training_check or {}).get("selected_step")
    if selected is not None:
        for ax in axes:
            ax.axvline(selected + 1, color="0.6", lw=0.8, ls="--")
    axes[0].set_ylabel("objective")
    axes[0].set_title(f"{result.scenario.name}: {result.objective} ({result.method})", fontsize=9)
    for i, name in enumerate(result.names):
        axes[i + 1].plot(steps, [h["gains"][i] for h in result.history])
        axes[i + 1].set_ylabel(name.split(".")[-1])
    axes[-1].set_xlabel("step")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


# ---- the tuners ----


def _schedule(learning_rate, steps):
    return optax.cosine_decay_schedule(learning_rate, max(steps, 1), alpha=0.1)


def default_optimizer(learning_rate: float, steps: int, clip: float = 1.0):
    """Adam on a cosine-decayed step (to 10 %) after clipping the gradient's global norm."""
    return optax.chain(optax.clip_by_global_norm(clip), optax.adam(_schedule(learning_rate, steps)))


def _temperatures(problem: _Problem, temperature, steps) -> list:
    if problem.law_temperature is None:
        return [None] * steps  # the law has no relaxation temperature
    start, end = (
        (problem.law_temperature, problem.law_temperature)
        if temperature is None
        else (temperature if isinstance(temperature, tuple) else (temperature, temperature))
    )
    if steps == 1:
        return [float(end)]
    return [float(start * (end / start) ** (s / (steps - 1))) for s in range(steps)]


def tune(
    scenario,
    params,
    objective=None,
    *,
    batch: int = 64,
    steps: int = 40,
    seed: int = 0,
    method: str = "adam",
    learning_rate: float = 0.1,
    optimizer=None,
    temperature=None,
    train_runs: int | None = None,
    heldout_runs: int = 1000,
    eval_every: int = 0,
    eval_runs: int = 256,
    gradient: str = "forward",
    population: int = 4,
    sigma: float = 0.1,
    confidence: float = 0.95,
    check_runs: int = 256,
    check_every: int | None = None,
    overrides=(),
    callback: Callable[[dict], None] | None = None,
) -> TuneResult:
    """Tune the gains ``params`` of ``scenario`` to minimise ``objective``.

    Args:
        scenario: a :class:`~gnc_jax.Scenario` or a packaged name / TOML path.
        params: scenario names of tunable leaves (a list, or comma-separated text).
        objective: built-in terms (:data:`TERMS`, e.g. ``"miss_rms+10*dv_mean"``), a mapping
            ``{term: weight}``, a callable ``fn(outcomes, weights)`` of the per-run outcomes
            (a NamedTuple of arrays, run on the first axis; weights 1 for ``ok`` runs, 0
            else), or ``None``: the system's ``smooth_objective``.
        batch: runs per step; steps: optimiser steps; seed: root seed of the run keys.
        method: ``"adam"`` (gradients through the relaxed laws) or ``"es"`` (gradient-free
            antithetic evolution strategy on the hard logic, same runs per step).
        learning_rate: of the default optimiser (:func:`default_optimizer`), in theta units
            (log of the gains: 0.1 is a 10 % change); optimizer: any optax transformation.
        temperature: relaxation temperature ``(start, end)`` annealed geometrically, or one
            number; default: constant at the scenario's own ``temperature``.
        train_runs: size of the training set of run indices (default ``batch * steps``).
        heldout_runs: held-out runs of the final paired evaluation (0: none).
        eval_every, eval_runs: evaluate the hard held-out objective on ``eval_runs`` held-out
            runs every ``eval_every`` steps (0: never) for :meth:`TuneResult.runs_to_reach`.
        gradient: ``"forward"`` (``jax.jacfwd``) or ``"reverse"`` (``jax.grad``).
        population, sigma: antithetic pairs per generation and the perturbation in theta
            (``method="es"``).
        check_runs, check_every: every ``check_every`` steps (default: an eighth of the
            steps) the hard objective of the gains on the first ``check_runs`` training runs;
            the result is the checked gains (or the start) where it is lowest
            (:attr:`TuneResult.training_check`); ``check_runs=0``: the last step's gains.
        overrides: ``section.field=value`` applied to ``scenario`` first.
        callback: called with each step's history record.

    Raises:
        ScenarioError: bad input (unknown or non-tunable gain, bad objective, bad sizes),
            before anything is compiled.
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario, overrides=overrides)
    elif overrides:
        scenario = scenario.with_overrides(overrides)
    for name, value, least in (
        ("batch", batch, 1),
        ("steps", steps, 1),
        ("heldout_runs", heldout_runs, 0),
        ("eval_every", eval_every, 0),
        ("eval_runs", eval_runs, 1),
        ("population", population, 1),
        ("check_runs", check_runs, 0),
        ("check_every", 1 if check_every is None else check_every, 1),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise ScenarioError(f"{name}: {value!r}; allowed: an integer >= {least}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ScenarioError(f"seed: {seed!r}; allowed: an integer in [0, 2^32)")
    if method not in ("adam", "es"):
        raise ScenarioError(f"method: {method!r}; allowed: adam, es")
    if gradient not in ("forward", "reverse"):
        raise ScenarioError(f"gradient: {gradient!r}; allowed: forward, reverse")
    train_runs = batch * steps if train_runs is None else train_runs
    if not 1 <= train_runs <= HELDOUT_OFFSET:
        raise ScenarioError(
            f"train_runs: {train_runs}; allowed: 1 .. {HELDOUT_OFFSET} (held-out indices start "
            "there)"
        )
    gains = resolve_gains(scenario, params)
    objective_ = parse_objective(objective, scenario)
    problem = _Problem(scenario, gains, objective_, seed)
    names = [g.name for g in gains]
    initial = [float(scenario[n]) for n in names]
    theta0 = problem.param.theta(initial)
    opt = optimizer or default_optimizer(learning_rate, steps)
    temps = _temperatures(problem, temperature, steps)
    run = _run_adam if method == "adam" else _run_es
    check_indices = np.arange(min(check_runs, train_runs))
    monitor = dict(
        eval_every=eval_every,
        eval_runs=eval_runs,
        check_runs=check_runs,
        check_every=max(steps // 8, 1) if check_every is None else check_every,
        check_indices=check_indices,
    )
    history, theta, compile_s, wall_s = run(
        problem, theta0, opt, temps, batch, steps, train_runs, gradient, population, sigma,
        monitor, callback, seed,
    )  # fmt: skip
    tuned = [float(x) for x in problem.param.gains(jnp.asarray(theta))]
    check = None
    if check_runs:
        # the result is the checked point (or the start) with the lowest hard objective on
        # the check's training runs: a relaxation that drifts late does not decide it
        checked = [(_hard_objective(problem, initial, check_indices), -1, initial)]
        checked += [(h["check"], h["step"], h["check_gains"]) for h in history if "check" in h]
        best = min(checked, key=lambda c: c[0])
        check = dict(
            runs=len(check_indices),
            initial=checked[0][0],
            last=checked[-1][0],
            tuned=best[0],
            selected_step=best[1],
        )
        tuned = list(best[2])
    tuned_scenario = _with_gains(scenario, names, tuned)
    heldout = (
        evaluate_heldout(problem, initial, tuned, heldout_runs, confidence=confidence)
        if heldout_runs
        else None
    )
    return TuneResult(
        scenario, tuned_scenario, names, initial, tuned, objective_.spec, method, seed, batch,
        steps, history, heldout, compile_s, wall_s, check,
    )  # fmt: skip


def _with_gains(scenario: Scenario, names, values) -> Scenario:
    tuned = scenario.with_overrides(dict(zip(names, values, strict=True)))
    return dataclasses.replace(
        tuned,
        paper={},  # the published numbers are for the paper's gains, not these
        name=f"{scenario.name}-tuned",
        description=f"{scenario.description} (tuned: "
        + ", ".join(f"{n.split('.')[-1]} = {v:.6g}" for n, v in zip(names, values, strict=True))
        + ")",
    )


def _record(problem, step, value, theta, temperature, runs, wall_s):
    return dict(
        step=step,
        objective=float(value),
        gains=[float(x) for x in problem.param.gains(jnp.asarray(theta))],
        temperature=temperature,
        runs=runs,
        wall_s=wall_s,
    )


def _run_adam(
    problem, theta, opt, temps, batch, steps, train_runs, gradient, population, sigma,
    monitor, callback, seed,
):  # fmt: skip
    def build_step():
        def value_and_grad(args, th, temperature, idx, valid):
            f = lambda t: problem.smooth(args, t, temperature, idx, valid)  # noqa: E731
            if gradient == "reverse":
                return jax.value_and_grad(f)(th)

            def twice(t):
                value = f(t)
                return value, value

            jac, value = jax.jacfwd(twice, has_aux=True)(th)
            return value, jac

        return value_and_grad

    t_arg = lambda s: None if temps[s] is None else np.float64(temps[s])  # noqa: E731
    idx, valid = problem.padded(train_indices(0, batch, train_runs))
    step_fn, compile_s = problem.compiled(
        f"adam-{gradient}", build_step, problem.args, theta, t_arg(0), idx, valid
    )
    update = _compiled_update(opt)
    state = opt.init(jnp.asarray(theta))
    history, wall = [], 0.0
    for s in range(steps):
        idx, valid = problem.padded(train_indices(s, batch, train_runs))
        t0 = time.perf_counter()
        value, grad = step_fn(problem.args, theta, t_arg(s), idx, valid)
        rec = _record(problem, s, value, theta, temps[s], (s + 1) * batch, 0.0)
        theta, state = update(np.asarray(grad), state, theta)
        theta = np.asarray(theta)
        wall += time.perf_counter() - t0
        rec["wall_s"] = wall
        _monitor(problem, rec, theta, s, steps, monitor)
        history.append(rec)
        if callback:
            callback(rec)
    return history, np.asarray(theta), compile_s, wall


def _compiled_update(opt):
    """The optimiser step, jitted (a non-finite gradient component counts as 0)."""

    def update(grad, state, theta):
        grad = jnp.where(jnp.isfinite(grad), grad, 0.0)
        updates, state = opt.update(grad, state, theta)
        return optax.apply_updates(theta, updates), state

    return jax.jit(update)


def _hard_objective(problem, gains, indices) -> float:
    idx, valid = problem.padded(indices)
    fn = problem.jitted("hard", lambda: problem.hard)
    return float(fn(problem.args, jnp.asarray(gains), idx, valid)[0])


def hard_objectives(scenario, params, objective, gains, runs: int, seed: int = 0) -> list[float]:
    """The hard objective of each gain vector of ``gains`` (file units) on the same ``runs``
    held-out runs: a grid check, a sweep or a baseline on the runs :func:`tune` holds out."""
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    resolved = resolve_gains(scenario, params)
    problem = _Problem(scenario, resolved, parse_objective(objective, scenario), seed)
    return [_hard_objective(problem, g, heldout_indices(runs)) for g in gains]


def _monitor(problem, rec, theta, s, steps, monitor):
    """Hard-logic checks after step ``s``'s update (their time is not in ``wall_s``): on the
    check's training runs every ``check_every`` steps (they select the result) and on held-out
    runs every ``eval_every`` steps (they only record)."""
    gains = [float(x) for x in problem.param.gains(jnp.asarray(theta))]
    last = s == steps - 1
    every = monitor["check_every"]
    if monitor["check_runs"] and every and ((s + 1) % every == 0 or last):
        rec["check"] = _hard_objective(problem, gains, monitor["check_indices"])
        rec["check_gains"] = gains
    every = monitor["eval_every"]
    if every and (s % every == 0 or last):
        rec["heldout"] = _hard_objective(problem, gains, heldout_indices(monitor["eval_runs"]))
        rec["heldout_gains"] = gains


def _run_es(
    problem, theta, opt, temps, batch, steps, train_runs, gradient, population, sigma,
    monitor, callback, seed,
):  # fmt: skip
    per_member = max(batch // (2 * population), 1)
    rng = np.random.default_rng(seed)

    def build_population():
        # a population of gains on common runs: the layer above the batch (STYLE: run ->
        # batch -> population)
        def population_values(args, thetas, idx, valid):
            return jax.vmap(lambda th: problem.hard(args, problem.param.gains(th), idx, valid)[0])(
                thetas
            )

        return population_values

    n = len(theta)
    idx, valid = problem.padded(train_indices(0, per_member, train_runs))
    members = np.zeros((2 * population + 1, n))
    fn, compile_s = problem.compiled("es", build_population, problem.args, members, idx, valid)
    update = _compiled_update(opt)
    state = opt.init(jnp.asarray(theta))
    history, wall = [], 0.0
    for s in range(steps):
        idx, valid = problem.padded(train_indices(s, per_member, train_runs))
        eps = rng.standard_normal((population, n))
        t0 = time.perf_counter()
        members = np.concatenate([theta[None], theta + sigma * eps, theta - sigma * eps])
        values = np.asarray(fn(problem.args, members, idx, valid))
        plus, minus = values[1 : population + 1], values[population + 1 :]
        grad = np.sum((plus - minus)[:, None] * eps, axis=0) / (2.0 * sigma * population)
        rec = _record(problem, s, values[0], theta, None, (s + 1) * per_member * 2 * population, 0)
        theta, state = update(grad, state, theta)
        theta = np.asarray(theta)
        wall += time.perf_counter() - t0
        rec["wall_s"] = wall
        _monitor(problem, rec, theta, s, steps, monitor)
        history.append(rec)
        if callback:
            callback(rec)
    return history, np.asarray(theta), compile_s, wall


def progress_line(rec: dict, names) -> str:
    """One line of training progress: step, objective, gains (and the held-out objective)."""
    gains = " ".join(
        f"{n.split('.')[-1]}={v:.5g}" for n, v in zip(names, rec["gains"], strict=True)
    )
    line = f"step {rec['step']:4d}  objective {rec['objective']:.6g}  {gains}"
    if rec.get("temperature") is not None:
        line += f"  T={rec['temperature']:.3g}"
    if rec.get("heldout") is not None:
        line += f"  held-out {rec['heldout']:.6g}"
    return line + f"  ({rec['wall_s']:.1f} s)"


__all__ = [
    "tune",
    "TuneResult",
    "Objective",
    "TERMS",
    "HELDOUT_OFFSET",
    "parse_objective",
    "resolve_gains",
    "train_indices",
    "heldout_indices",
    "evaluate_heldout",
    "hard_objectives",
    "paired_interval",
    "progress_line",
]
