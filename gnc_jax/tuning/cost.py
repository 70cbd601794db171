"""What a tuning will cost, estimated before anything is built or compiled
(:func:`checked_tune_cost`): each kind of compiled call it makes (a training step, a hard
check, a held-out evaluation) costed by :func:`~gnc_jax.estimate_cost` as a study of that
call's runs, a gradient step's runs weighted by an upper bound of a gradient's measured cost.

**The gradient's weight.** One gradient step of a batch costs, in plain runs of the same
batch (one step of 256 runs, compile apart, docs/howto/tune.md and
``benchmarks/tune_gradient.py``): forward mode 3.2x for the impactor's 2 gains, 10.3x for the
intercept's 4, 10.7x for the capsule's 4, 4.2x / 29x for 2 / 32 parameters mapped into the LOS
law's gains, bounded by ``3 + 2 p`` (:data:`FORWARD_COST`); the tuner's reverse mode 3.2-3.4x
for the capsule and 5-12x for the impactor whatever the number of parameters (11-12x its CPU
time at load 8-11), bounded by :data:`REVERSE_COST`, on one device where the system runs its
reverse mode unsharded. The estimate is meant to catch a runaway tuning (a held-out set of
10^8 runs, 10^5 steps), not to time one: an over-estimate by the bound's margin is intended.
"""

from ..backend import Backend
from ..planner import CostEstimate, estimate_cost
from ..scenario import Scenario, ScenarioError
from .optimisers import gradient_mode

FORWARD_COST = (3.0, 2.0)
"""``(a, b)``: a forward-mode gradient of ``p`` parameters costs at most ``a + b p`` plain runs
(module docstring)."""
REVERSE_COST = 12.0
"""The tuner's reverse-mode gradient costs at most this many plain runs (module docstring)."""


def _calls(method, gradient, n_params, reverse_on_one_device, sizes) -> list:
    """``(label, calls, runs per call, weight, devices or None)`` of each kind of compiled call
    a tuning makes (the loops of :mod:`~gnc_jax.tuning.optimisers` and
    :func:`~gnc_jax.tuning.tuner.tune`)."""
    batch, steps, population = sizes["batch"], sizes["steps"], sizes["population"]
    if method == "adam":
        a, b = FORWARD_COST
        weight = REVERSE_COST if gradient == "reverse" else a + b * n_params
        label = f"{steps} steps x {batch} runs x {weight:g} ({gradient}-mode gradient)"
        devices = 1 if gradient == "reverse" and reverse_on_one_device else None
        calls = [(label, steps, batch, weight, devices)]
    else:  # a population of 2 x population + 1 members on common runs each step
        members = (2 * population + 1) * max(batch // (2 * population), 1)
        calls = [(f"{steps} steps x {members} runs", steps, members, 1.0, None)]
    check_runs, every = min(sizes["check_runs"], sizes["train_runs"]), sizes["check_every"]
    if check_runs:  # the start, then every check_every steps and the last
        checks = 1 + steps // every + (1 if steps % every else 0)
        calls.append((f"{checks} checks x {check_runs} runs", checks, check_runs, 1.0, None))
    every, eval_runs = sizes["eval_every"], sizes["eval_runs"]
    if every:  # steps 0, every, 2 every, ... and the last
        evals = -(-steps // every) + (1 if (steps - 1) % every else 0)
        calls.append((f"{evals} evaluations x {eval_runs} runs", evals, eval_runs, 1.0, None))
    if sizes["heldout_runs"]:
        held = sizes["heldout_runs"]
        calls.append((f"2 x {held} held-out runs", 2, held, 1.0, None))
    return calls


def tune_cost(
    scenario: Scenario, backend: Backend, method: str, gradient: str, n_params: int, **sizes
) -> tuple[CostEstimate, str]:
    """``(estimate, breakdown)``: a :class:`~gnc_jax.planner.CostEstimate` of the tuning's
    calls in plain runs (a gradient run weighted as in the module docstring) and the text of
    its terms. ``sizes``: ``batch, steps, population, train_runs, check_runs, check_every,
    eval_every, eval_runs, heldout_runs`` as :func:`~gnc_jax.tuning.tune` takes them."""
    system = scenario.system
    reverse_devices = backend.count if system.reverse_on_one_device else 1
    gradient = gradient_mode(gradient, n_params, system.gradient_costs, reverse_devices)
    calls = _calls(method, gradient, n_params, system.reverse_on_one_device, sizes)
    runs, seconds, latency = 0, 0.0, 0.0
    for _, n, per_call, weight, devices in calls:
        one = estimate_cost(scenario, per_call, devices, backend)
        runs += round(n * per_call * weight)
        if seconds is not None and one.seconds is not None:
            seconds += n * weight * one.seconds
            latency += n * weight * one.latency_s
        else:
            seconds = None
    if seconds is None:
        latency = 0.0
    whole = estimate_cost(scenario, 1, None, backend)
    estimate = CostEstimate(
        runs, whole.steps_per_run, whole.n_devices, seconds, whole.platform, latency, whole.source
    )
    return estimate, " + ".join(c[0] for c in calls)


def checked_tune_cost(scenario, backend, method, gradient, n_params, max_hours, **sizes) -> None:
    """:func:`tune_cost`, refused (:class:`ScenarioError`, one line) above ``max_hours``."""
    estimate, breakdown = tune_cost(scenario, backend, method, gradient, n_params, **sizes)
    if estimate.seconds is not None and estimate.seconds > max_hours * 3600:
        raise ScenarioError(
            f"cost: tune of {breakdown} = {estimate}; allowed: at most {max_hours:g} h (raise "
            "max_hours, CLI --max-hours, or use fewer steps, a smaller batch or fewer held-out "
            "runs)"
        )
