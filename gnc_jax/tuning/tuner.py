"""``tune``: the gains of a scenario tuned on dispersed runs, from the checked arguments to
the held-out evaluation of the result."""

import dataclasses
import importlib.util
from collections.abc import Callable
from math import inf
from numbers import Real

import jax.numpy as jnp
import numpy as np

from ..backend import placement, select
from ..montecarlo import MAX_HOURS
from ..scenario import Scenario, ScenarioError, load_scenario
from .cost import checked_tune_cost
from .evaluation import _hard_scored, evaluate_heldout, ranking_key
from .objectives import parse_objective
from .optimisers import (
    _run_adam,
    _run_cma,
    _run_es,
    _temperatures,
    default_optimizer,
    gradient_mode,
)
from .parametrisation import resolve_gains, with_schedule_starts
from .problem import HELDOUT_MAX_RUNS, HELDOUT_OFFSET, TuningProblem
from .result import TuneResult


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
    gradient: str = "auto",
    population: int = 4,
    sigma: float = 0.1,
    confidence: float = 0.95,
    check_runs: int = 256,
    check_every: int | None = None,
    overrides=(),
    callback: Callable[[dict], None] | None = None,
    device: str | None = None,
    max_hours: float = MAX_HOURS,
) -> TuneResult:
    """Tune the gains ``params`` of ``scenario`` to minimise ``objective``.

    Long only for its 23 arguments and their documentation: the steps (the checks of the
    sizes, the tuner's loop, the selection by the training check, the held-out evaluation)
    are functions of their own.

    Args:
        scenario: a :class:`~gnc_jax.Scenario` or a packaged name / TOML path.
        params: scenario names of tunable leaves (a list, or comma-separated text); a
            schedule (``guidance.los.k1_schedule``) is one parameter per knot, an empty one
            starting at its constant gain (:func:`~gnc_jax.tuning.with_schedule_starts`).
        objective: built-in terms (:data:`TERMS`, e.g. ``"miss_rms+10*dv_mean"``), a mapping
            ``{term: weight}``, a callable ``fn(outcomes, weights)`` of the per-run outcomes
            (a NamedTuple of arrays, run on the first axis; weights 1 for ``ok`` runs, 0
            for the failed runs and the batch's padding) or ``fn(outcomes, weights, runs)``
            (``runs`` 1 for the batch's runs, 0 for its padding: ``runs - weights`` marks the
            failed runs), or ``None``: the system's ``smooth_objective``.
        batch: runs per step; steps: optimiser steps; seed: root seed of the run keys.
        method: ``"adam"`` (gradients through the relaxed laws), ``"es"`` (gradient-free
            antithetic evolution strategy on the hard logic, same runs per step) or
            ``"cma"`` (CMA-ES from the ``cma`` package, hard logic, same runs per step).
        learning_rate: of the default optimiser (:func:`default_optimizer`), in theta units
            (log of the gains: 0.1 is a 10 % change); optimizer: any optax transformation.
        temperature: relaxation temperature ``(start, end)`` annealed geometrically, or one
            number; default: constant at the scenario's own ``temperature``.
        train_runs: size of the training set of run indices (default ``batch * steps``).
        heldout_runs: held-out runs of the final paired evaluation (0: none).
        eval_every, eval_runs: evaluate the hard held-out objective on ``eval_runs`` held-out
            runs every ``eval_every`` steps (0: never) for :meth:`TuneResult.runs_to_reach`.
        gradient: ``"forward"`` (``jax.jacfwd``: a tangent per parameter), ``"reverse"``
            (``jax.grad`` through the system's checkpointed loops: a cost that does not grow
            with the parameters) or ``"auto"``: the cheaper by the system's measured costs and
            the devices (:func:`~gnc_jax.tuning.optimisers.gradient_mode`), by default reverse
            from :data:`~gnc_jax.tuning.optimisers.REVERSE_FROM` parameters on.
        population, sigma: antithetic pairs per generation and the perturbation in theta
            (``method="es"``; for ``"cma"``: ``2 x population`` candidates, initial step).
        check_runs, check_every: every ``check_every`` steps (default: an eighth of the
            steps) the hard objective of the gains on the first ``check_runs`` training runs;
            the result is the checked gains (or the start) where it is lowest
            (:attr:`TuneResult.training_check`); ``check_runs=0``: the last step's gains.
        overrides: ``section.field=value`` applied to ``scenario`` first.
        callback: called with each step's history record.
        device: ``"cpu"``, ``"gpu"`` or ``"auto"`` (default), as in :func:`gnc_jax.run_study`.
        max_hours: refuse (before anything is compiled) a tuning whose cost estimate
            (:func:`~gnc_jax.tuning.cost.tune_cost`: the training steps, a gradient's runs at
            an upper bound of its measured cost, the checks and the held-out runs) exceeds
            this many hours.

    Raises:
        ScenarioError: bad input (unknown or non-tunable gain, bad objective, bad sizes, a
            cost above ``max_hours``), before anything is compiled.
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario, overrides=overrides)
    elif overrides:
        scenario = scenario.with_overrides(overrides)
    train_runs = _checked_sizes(
        batch, steps, seed, method, gradient, train_runs, heldout_runs, eval_every, eval_runs,
        population, check_runs, check_every, learning_rate, sigma,
    )  # fmt: skip
    _check_temperature(temperature)
    if isinstance(max_hours, bool) or not isinstance(max_hours, Real) or not 0 < max_hours < inf:
        raise ScenarioError(f"max_hours: {max_hours!r}; allowed: a finite number > 0")
    check_every = max(steps // 8, 1) if check_every is None else check_every
    scenario = with_schedule_starts(scenario, params)
    gains = resolve_gains(scenario, params)
    objective_ = parse_objective(objective, scenario)
    backend = select(device)
    checked_tune_cost(
        scenario, backend, method, gradient, len(gains), max_hours, batch=batch, steps=steps,
        population=population, train_runs=train_runs, check_runs=check_runs,
        check_every=check_every, eval_every=eval_every, eval_runs=eval_runs,
        heldout_runs=heldout_runs,
    )  # fmt: skip
    with placement(backend):  # the gains, the runs and the optimiser on that platform
        problem = TuningProblem(scenario, gains, objective_, seed, backend)
        names = [g.name for g in gains]
        initial = [g.start(scenario) for g in gains]
        theta0 = problem.param.theta(initial)
        opt = optimizer or default_optimizer(learning_rate, steps)
        temps = _temperatures(problem, temperature, steps)
        run = {"adam": _run_adam, "es": _run_es, "cma": _run_cma}[method]
        check_indices = np.arange(min(check_runs, train_runs))
        monitor = dict(
            eval_every=eval_every,
            eval_runs=eval_runs,
            check_runs=check_runs,
            check_every=check_every,
            check_indices=check_indices,
        )
        system = problem.system
        reverse_devices = problem.n_dev if system.reverse_on_one_device else 1
        gradient = gradient_mode(gradient, len(names), system.gradient_costs, reverse_devices)
        history, theta, compile_s, wall_s = run(
            problem, theta0, opt, temps, batch, steps, train_runs, gradient, population, sigma,
            monitor, callback, seed,
        )  # fmt: skip
        tuned = [float(x) for x in problem.param.gains(jnp.asarray(theta))]
        check = None
        if check_runs:
            check, tuned = _training_check(problem, initial, check_indices, history)
        tuned_scenario = _with_gains(scenario, gains, tuned)
        heldout = (
            evaluate_heldout(problem, initial, tuned, heldout_runs, confidence=confidence)
            if heldout_runs
            else None
        )
        return TuneResult(
            scenario, tuned_scenario, names, initial, tuned, objective_.spec, method, seed, batch,
            steps, history, heldout, compile_s, wall_s, check,
            gradient if method == "adam" else None,
        )  # fmt: skip


def _checked_sizes(
    batch, steps, seed, method, gradient, train_runs, heldout_runs, eval_every, eval_runs,
    population, check_runs, check_every, learning_rate, sigma,
) -> int:  # fmt: skip
    """The training set's size (default ``batch * steps``) once every size, the steps
    (``learning_rate``, ``sigma``), the seed, the method and the gradient mode are checked;
    :class:`ScenarioError` naming the first bad one."""
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
    for name, value in (("learning_rate", learning_rate), ("sigma", sigma)):
        if isinstance(value, bool) or not isinstance(value, Real) or not 0 < value < inf:
            raise ScenarioError(f"{name}: {value!r}; allowed: a finite number > 0")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32:
        raise ScenarioError(f"seed: {seed!r}; allowed: an integer in [0, 2^32)")
    if method not in ("adam", "es", "cma"):
        raise ScenarioError(f"method: {method!r}; allowed: adam, es, cma")
    if method == "cma" and importlib.util.find_spec("cma") is None:
        raise ScenarioError(
            "method: 'cma' needs the cma package, not installed; allowed: adam, es, or cma "
            "after pip install 'gnc_jax[tune]'"
        )
    if gradient not in ("auto", "forward", "reverse"):
        raise ScenarioError(f"gradient: {gradient!r}; allowed: auto, forward, reverse")
    train_runs = batch * steps if train_runs is None else train_runs
    if not 1 <= train_runs <= HELDOUT_OFFSET:
        raise ScenarioError(
            f"train_runs: {train_runs}; allowed: 1 .. {HELDOUT_OFFSET} (held-out indices start "
            "there)"
        )
    for name, value in (("heldout_runs", heldout_runs), ("eval_runs", eval_runs)):
        if value > HELDOUT_MAX_RUNS:
            raise ScenarioError(
                f"{name}: {value}; allowed: at most {HELDOUT_MAX_RUNS} (held-out indices from "
                f"{HELDOUT_OFFSET} to 2^32 - 1: a run's key takes its index modulo 2^32)"
            )
    return train_runs


def _check_temperature(temperature) -> None:
    """``temperature``: ``None``, one number or a ``(start, end)`` pair, each finite and > 0;
    :class:`ScenarioError` otherwise."""
    if temperature is None:
        return
    values = temperature if isinstance(temperature, tuple) else (temperature,)
    positive = (isinstance(v, Real) and not isinstance(v, bool) and 0 < v < inf for v in values)
    if len(values) != (2 if isinstance(temperature, tuple) else 1) or not all(positive):
        raise ScenarioError(
            f"temperature: {temperature!r}; allowed: a finite number > 0 or a pair (start, end) "
            "of them"
        )


def _training_check(problem, initial, check_indices, history) -> tuple[dict, list]:
    """``(training_check, tuned gains)``: the result is the checked point (or the start) with
    the fewest failed runs and, among those, the lowest hard objective on the check's training
    runs (:func:`~.evaluation.ranking_key`), so that a relaxation that drifts late does not
    decide it, nor a gain that turns runs into failures."""
    checked = [(*_hard_scored(problem, initial, check_indices), -1, initial)]
    checked += [
        (h["check"], h["check_failed"], h["step"], h["check_gains"])
        for h in history
        if "check" in h
    ]
    best = min(checked, key=lambda c: ranking_key(c[0], c[1]))
    check = dict(
        runs=len(check_indices),
        initial=checked[0][0],
        last=checked[-1][0],
        tuned=best[0],
        selected_step=best[2],
        failed=dict(initial=checked[0][1], last=checked[-1][1], tuned=best[1]),
    )
    return check, list(best[3])


def _with_gains(scenario: Scenario, gains, values) -> Scenario:
    fields: dict = {}
    for g, v in zip(gains, values, strict=True):
        if g.index is None:
            fields[g.field] = v
        else:
            fields.setdefault(g.field, []).append(v)
    tuned = scenario.with_overrides(fields)
    names = [g.name for g in gains]
    return dataclasses.replace(
        tuned,
        paper={},  # the published numbers are for the paper's gains, not these
        name=f"{scenario.name}-tuned",
        description=f"{scenario.description} (tuned: "
        + ", ".join(f"{n.split('.')[-1]} = {v:.6g}" for n, v in zip(names, values, strict=True))
        + ")",
    )
