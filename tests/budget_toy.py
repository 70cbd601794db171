"""A toy system for the error budget, registered from the tests like a user's system.

``y = c0 w0 + c1 w1 + c2 w2 + p w1 w2`` with ``w_s`` independent standard normals, each from
its own stream and its own source ``s0, s1, s2``. Its variance shares are known in closed
form: ``Var y = c0^2 + c1^2 + c2^2 + p^2``; first-order ``S_s = c_s^2 / Var y``; total
``ST_s = S_s + p^2 / Var y`` for ``s1, s2`` (the product's share is their interaction).
"""

import pathlib
from typing import ClassVar, NamedTuple

import jax.numpy as jnp
import numpy as np

from gnc_jax import ErrorSource, stream_normal
from gnc_jax.schema import Field
from gnc_jax.systems import AbstractSystem, register_system


class ToyBudgetOutcome(NamedTuple):
    status: jnp.ndarray
    y: jnp.ndarray


@register_system
class ToyBudgetSystem(AbstractSystem):
    name = "toy-budget"
    description = "y = c0 w0 + c1 w1 + c2 w2 + p w1 w2 (the error budget's oracle)"
    sections: ClassVar = {
        "coefficients": {
            n: Field("float", d, lo=-100.0, hi=100.0)
            for n, d in (("c0", 1.0), ("c1", 2.0), ("c2", 3.0), ("p", 0.0))
        }
    }
    error_sources: ClassVar = {
        f"s{i}": ErrorSource((f"coefficients.c{i}", "coefficients.p"), (((i,),),)) for i in range(3)
    }
    source_groups: ClassVar = {"s12": ("s1", "s2")}
    budget_metrics: ClassVar = {"y": lambda o: o["y"]}

    def build(self, scenario):
        c = scenario.config["coefficients"]
        return jnp.array([c["c0"], c["c1"], c["c2"], c["p"]]), None

    def simulate(self, params, law, key, record=False):
        w = jnp.stack([stream_normal(key, i, ())[()] for i in range(3)])
        y = jnp.dot(params[:3], w) + params[3] * w[1] * w[2]
        return ToyBudgetOutcome(jnp.zeros((), jnp.int32), y), None

    def statistics(self, outcomes, ok):
        return dict(y_var=float(np.var(outcomes["y"][ok]))) if ok.any() else {}


def toy_scenario(**coefficients):
    """The toy's scenario with ``coefficients`` (``c0=1.0, p=2.0``) overridden."""
    import gnc_jax as gj

    path = pathlib.Path(__file__).with_name("toy_budget.toml")
    return gj.load_scenario(path, {f"coefficients.{k}": v for k, v in coefficients.items()})
