"""The gains to tune (:func:`resolve_gains`) and their unconstrained parameters
(:class:`Reparametrisation`).

**Constraints by reparametrisation.** The optimiser moves ``theta`` (one number per gain,
unconstrained): a gain with a lower bound ``lo`` is ``lo + exp(theta)`` (a log scale, so Adam's
steps are relative changes); a pair the law needs ordered (``ordered_gains`` of the law class:
k1 >= k2, trigger_on > trigger_off) is ``smaller = lo + exp(theta_s)``, ``larger = smaller +
exp(theta_l)``; upper bounds clip.

**Schedules.** A gain schedule (``guidance.los.k1_schedule``: the law's ``schedules``) is
tuned knot by knot: its name stands for one parameter per breakpoint (``k1_schedule[j]``),
each on its own log scale, and an ordered pair holds at every knot (k1[j] >= k2[j]). An empty
schedule starts at its constant gain at every breakpoint (:func:`with_schedule_starts`),
which flies bit-identically to the constant gain.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..params import declared_params
from ..scenario import Scenario, ScenarioError
from ..systems.base import tunable_leaf


@dataclasses.dataclass(frozen=True)
class Gain:
    """A tunable leaf: its scenario name, the law attribute, the factor from the file's units
    to the law's SI leaf, and its allowed range (file units)."""

    name: str
    attribute: str
    si_per_file: float
    lo: float | None
    hi: float | None
    index: int | None = None  # the knot of a schedule (name: ``field[index]``), else None

    @property
    def field(self) -> str:
        """The scenario name of the field (a schedule's, for a knot)."""
        return self.name.split("[")[0]

    def start(self, scenario: Scenario) -> float:
        """The gain's value in ``scenario`` (file units)."""
        value = scenario[self.field]
        return float(value if self.index is None else value[self.index])


def _law_schedules(scenario: Scenario) -> tuple[type, str, dict]:
    system = scenario.system
    law_name = system.law_name(scenario.config)
    cls = system.laws()[law_name]
    return cls, law_name, dict(getattr(cls, "schedules", {}))


def with_schedule_starts(scenario: Scenario, names) -> Scenario:
    """``scenario`` with each named empty schedule set to its constant gain at every
    breakpoint (the start of a schedule's tuning; the same flight as the constant gain);
    :class:`ScenarioError` when the law has no breakpoints set."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    cls, law_name, schedules = _law_schedules(scenario)
    filled = {}
    for name in names:
        field = name.split(".")[-1]
        if name != f"guidance.{law_name}.{field}" or field not in schedules:
            continue
        if len(scenario[name]):
            continue
        where = f"guidance.{law_name}.{cls.schedule_breakpoints}"
        n = len(scenario[where])
        if n < 2:
            raise ScenarioError(
                f"{where}: {n} breakpoints, so {name} has no knots to tune; allowed: at least "
                "2 increasing breakpoints (--set)"
            )
        filled[name] = [float(scenario[f"guidance.{law_name}.{schedules[field]}"])] * n
    return scenario.with_overrides(filled) if filled else scenario


def resolve_gains(scenario: Scenario, names) -> list[Gain]:
    """The :class:`Gain` of each scenario name; :class:`ScenarioError` (one line naming the
    field and the allowed names) for an unknown or non-tunable name, or a gain of a law the
    scenario does not fly. Nothing is built."""
    system = scenario.system
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    law_name = system.law_name(scenario.config)
    own = [n for n in system.tunable_names() if n.startswith(f"guidance.{law_name}.")]
    if not own:
        raise ScenarioError(
            f"params: scenario {scenario.name} ({system.name}, guidance.law = {law_name!r}) has "
            "no tunable gain; allowed: a scenario whose law declares tunable gains (gnc-jax "
            "list --fields)"
        )
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
        scheduled = _scheduled_gains(scenario)
        if name.split(".")[-1] in scheduled:
            raise ScenarioError(
                f"{name}: its schedule {scheduled[name.split('.')[-1]]} is set and replaces "
                f"it; allowed: tune guidance.{law_name}.{scheduled[name.split('.')[-1]]}"
            )
        value = scenario[name]
        knots = [None] if spec.field.kind != "floats" else list(range(len(value)))
        if not knots:
            raise ScenarioError(f"{name}: an empty schedule; allowed: knots to tune (--set)")
        for j in knots:
            gain = Gain(name if j is None else f"{name}[{j}]", attribute, float("nan"), lo,
                        spec.field.hi, j)  # fmt: skip
            if lo is not None and gain.start(scenario) <= lo:
                raise ScenarioError(
                    f"{gain.name}: {gain.start(scenario):g} is at its lower bound {lo:g}, where "
                    f"the log reparametrisation cannot start; allowed: a start value > {lo:g}"
                )
            gains.append(gain)
    if len(set(names)) != len(names):
        raise ScenarioError(f"params: {','.join(names)} names a gain twice; allowed: each once")
    return gains


def _scheduled_gains(scenario: Scenario) -> dict[str, str]:
    """``{gain: its schedule}`` of the law's gains whose schedule is set (non-empty)."""
    _, law_name, schedules = _law_schedules(scenario)
    return {g: s for s, g in schedules.items() if len(scenario[f"guidance.{law_name}.{s}"])}


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
        cls, law_name, schedules = _law_schedules(scenario)
        gain_of = lambda f: schedules.get(f, f)  # noqa: E731 - a schedule orders as its gain
        keys = [(gain_of(g.field.split(".")[-1]), g.index) for g in gains]
        below = [-1] * len(gains)
        above_fixed: list = [None] * len(gains)
        below_fixed: list = [None] * len(gains)
        for larger, smaller in cls.ordered_gains:
            for i, (base, j) in enumerate(keys):
                other = smaller if base == larger else larger if base == smaller else None
                if other is None:
                    continue
                partner = [m for m, k in enumerate(keys) if k[0] == other and k[1] in (j, None)]
                if partner and base == larger:
                    below[i] = partner[0]
                elif not partner:
                    fixed = _effective(scenario, law_name, schedules, other, j)
                    if base == larger:
                        above_fixed[i] = max(fixed)
                    else:
                        below_fixed[i] = min(fixed)
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


def _effective(scenario, law_name, schedules, gain, knot) -> list[float]:
    """The values the law flies for ``gain`` (file name): its schedule's knot ``knot`` (all
    knots for ``None``) when the schedule is set, else the constant gain."""
    schedule = {g: s for s, g in schedules.items()}.get(gain)
    values = scenario[f"guidance.{law_name}.{schedule}"] if schedule else []
    if len(values):
        return [float(v) for v in (values if knot is None else [values[knot]])]
    return [float(scenario[f"guidance.{law_name}.{gain}"])]
