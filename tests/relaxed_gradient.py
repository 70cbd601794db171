"""The tuner's relaxed objective of a system's cheap test scenario, for the gradient checks of
the closed loops (reverse mode against forward mode and differences)."""

import jax.numpy as jnp
import numpy as np

import gnc_jax as gj
from gnc_jax import tuning


def relaxed_objective(scenario: str, system: str, names: list[str], runs: int = 2):
    """``(f, problem, theta)``: ``f(args, theta, gradient="forward")`` is the relaxed objective
    of the gains ``names`` (at the law's temperature) over the first ``runs`` runs of
    ``scenario`` with ``system``'s ``test_overrides``; ``theta`` the scenario's own gains in the
    tuner's units; ``problem.args`` and ``problem.args_for("reverse")`` its first argument in
    either mode."""
    sc = gj.load_scenario(scenario, overrides=gj.get_system(system).test_overrides)
    problem = tuning.TuningProblem(
        sc, tuning.resolve_gains(sc, names), tuning.parse_objective(None, sc), 0
    )
    theta = jnp.asarray(problem.param.theta([sc[n] for n in names]))
    idx, valid = problem.padded(np.arange(runs))

    def f(args, th, gradient="forward"):
        return problem.smooth(args, th, problem.law_temperature, idx, valid, gradient)

    return f, problem, theta
