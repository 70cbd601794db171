"""The gains to tune (:func:`resolve_gains`) and their unconstrained parameters
(:class:`Reparametrisation`).

**Constraints by reparametrisation.** The optimiser moves ``theta`` (one number per gain,
unconstrained): a gain with a lower bound ``lo`` is ``lo + exp(theta)`` (a log scale, so Adam's
steps are relative changes); a pair the law needs ordered (``ordered_gains`` of the law class:
k1 >= k2, trigger_on > trigger_off) is ``smaller = lo + exp(theta_s)``, ``larger = smaller +
exp(theta_l)``; upper bounds clip.
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
