"""The two tuners: Adam on gradients through the relaxed laws (:func:`_run_adam`) and an
antithetic evolution strategy on the hard logic (:func:`_run_es`), with their schedule,
temperatures, hard-logic checks and progress records.

**Forward or reverse mode, by the number of parameters.** ``gradient="forward"`` is
``jax.jacfwd`` (one tangent per parameter, vectorised), ``"reverse"`` is ``jax.grad`` through
the loops the system sets up for it (:meth:`~gnc_jax.systems.AbstractSystem.reverse_mode`):
the impactor checkpoints each image step of its scan (one loop state kept per image, an
image's control steps recomputed on the way back, each of them checkpointed in turn); the
capsule flies its cycles in equinox's checkpointed ``while_loop`` (the same trip counts and
arithmetic as its ``lax.while_loop``, bounded memory) and differentiates its corrector's
solutions by the implicit function theorem, or, when every tuned gain acts only after its
last solution (its tracking gains), passes none through them. ``"auto"`` (the default) takes
the cheaper mode by the system's measured costs
(:attr:`~gnc_jax.systems.AbstractSystem.gradient_costs`), by default reverse mode from
:data:`REVERSE_FROM` parameters on. Measured with
``benchmarks/tune_gradient.py --only impactor --modes value,forward,reverse --params
2,4,6,8`` (deep-impact-los, 256 runs, one step, compile apart, the shared 2-core machine at
load 2-4, wall time): value 0.22 s; forward mode 0.60 / 0.89 / 0.98 / 1.24 s for 2 / 4 / 6 / 8
parameters; reverse mode 0.91-1.29 s whatever the number, peak RSS 1.8-2.0x the value's against
1.3-1.5x for forward mode: the LOS loop's crossover is at 6-8 parameters, and ten, the
default, is above it: forward mode for a law's few gains, reverse mode for schedules. The
capsule's is below one parameter on one device: forward mode 4.3x a value with one tangent and
10.7x with its four gains, the tuner's reverse mode 3.2-3.4x whatever the number (``--only
capsule --modes value,forward,reverse --params 0,1,2,16,32``, idle; its ``gradient_costs``).
Its reverse mode runs on one device where forward mode shards: with two devices forward mode
is the cheaper for one or two parameters, with sixteen up to about 24.

**Gradient-free baseline** (``method="es"``): an antithetic evolution strategy in the same
``theta`` with the same optimiser, evaluated with the hard logic; each generation flies
``2 x population`` members on ``batch // (2 x population)`` common runs, so it simulates the
same number of runs per step as the gradient tuner (the same budget in runs). ``eval_every``
records the held-out objective along the way (:meth:`TuneResult.runs_to_reach`).

**CMA-ES baseline** (``method="cma"``): the ``cma`` package's covariance-matrix adaptation
(an optional dependency: ``pip install gnc_jax[tune]``) in the same ``theta``, ``sigma`` its
initial step; each generation flies ``2 x population`` candidates and the distribution's mean
on the same ``batch // (2 x population)`` common runs of the hard logic as the ES, so the
three methods simulate the same runs per step. The gains of a step are CMA-ES's mean.
"""

import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from .evaluation import _hard_scored, lexicographic_scores
from .problem import TuningProblem, heldout_indices, train_indices

REVERSE_FROM = 10
"""``gradient="auto"`` takes reverse mode from this many tuned parameters on (the measured
crossover: see the module docstring), forward mode below it."""


def gradient_mode(gradient: str, n_params: int, costs=None, reverse_devices: int = 1) -> str:
    """``"forward"`` or ``"reverse"``: ``gradient`` itself, or for ``"auto"`` the cheaper for
    ``n_params`` tuned parameters. With a system's measured ``costs`` ``(a, b, r)``
    (:attr:`~gnc_jax.systems.AbstractSystem.gradient_costs`): reverse mode where ``r`` times
    ``reverse_devices`` is below ``a + b n_params`` (``reverse_devices``: the devices forward
    mode shards a batch over where reverse mode runs it on one); without, reverse mode from
    :data:`REVERSE_FROM` parameters on."""
    if gradient != "auto":
        return gradient
    if costs is None:
        return "reverse" if n_params >= REVERSE_FROM else "forward"
    a, b, r = costs
    return "reverse" if r * reverse_devices < a + b * n_params else "forward"


def _schedule(learning_rate, steps):
    return optax.cosine_decay_schedule(learning_rate, max(steps, 1), alpha=0.1)


def default_optimizer(learning_rate: float, steps: int, clip: float = 1.0):
    """Adam on a cosine-decayed step (to 10 %) after clipping the gradient's global norm."""
    return optax.chain(optax.clip_by_global_norm(clip), optax.adam(_schedule(learning_rate, steps)))


def _temperatures(problem: TuningProblem, temperature, steps) -> list:
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
            return problem.value_and_grad(args, th, temperature, idx, valid, gradient)

        return value_and_grad

    t_arg = lambda s: None if temps[s] is None else np.float64(temps[s])  # noqa: E731
    idx, valid = problem.padded(train_indices(0, batch, train_runs))
    args = problem.args_for(gradient)
    step_fn, compile_s = problem.compiled(
        f"adam-{gradient}", build_step, args, theta, t_arg(0), idx, valid
    )
    update, state, update_s = _compiled_update(opt, theta)
    compile_s += update_s
    history, wall = [], 0.0
    for s in range(steps):
        idx, valid = problem.padded(train_indices(s, batch, train_runs))
        t0 = time.perf_counter()
        value, grad = step_fn(args, theta, t_arg(s), idx, valid)
        grad = np.asarray(grad)
        stepped, state = update(grad, state, theta)
        stepped = np.asarray(stepped)
        wall += time.perf_counter() - t0  # the record's bookkeeping is not training
        rec = _record(problem, s, value, theta, temps[s], (s + 1) * batch, wall)
        nonfinite = int(np.sum(~np.isfinite(grad)))
        if nonfinite:  # taken as 0 by the update: flagged, not followed silently
            rec["nonfinite_gradient"] = nonfinite
        theta = stepped
        _monitor(problem, rec, theta, s, steps, monitor)
        history.append(rec)
        if callback:
            callback(rec)
    return history, np.asarray(theta), compile_s, wall


def _compiled_update(opt, theta):
    """The optimiser step compiled ahead of time for ``theta`` (a non-finite gradient component
    counts as 0), the optimiser's initial state and the compile time (counted in the tuner's
    compile time, not in its training time)."""

    def update(grad, state, theta):
        grad = jnp.where(jnp.isfinite(grad), grad, 0.0)
        updates, state = opt.update(grad, state, theta)
        return optax.apply_updates(theta, updates), state

    theta = jnp.asarray(theta)
    state = opt.init(theta)
    t0 = time.perf_counter()
    executable = jax.jit(update).lower(theta, state, theta).compile()
    return executable, state, time.perf_counter() - t0


def _monitor(problem, rec, theta, s, steps, monitor):
    """Hard-logic checks after step ``s``'s update (their time is not in ``wall_s``): on the
    check's training runs every ``check_every`` steps (they select the result) and on held-out
    runs every ``eval_every`` steps (they only record)."""
    gains = [float(x) for x in problem.param.gains(jnp.asarray(theta))]
    last = s == steps - 1
    every = monitor["check_every"]
    if monitor["check_runs"] and every and ((s + 1) % every == 0 or last):
        rec["check"], rec["check_failed"] = _hard_scored(problem, gains, monitor["check_indices"])
        rec["check_gains"] = gains
    every = monitor["eval_every"]
    if every and (s % every == 0 or last):
        rec["heldout"], rec["heldout_failed"] = _hard_scored(
            problem, gains, heldout_indices(monitor["eval_runs"])
        )
        rec["heldout_gains"] = gains


def _population(problem):
    """The builder of the hard objective of a population of ``theta`` on common runs: the
    layer above the batch (STYLE: run -> batch -> population), shared by the ES and CMA-ES."""

    def build():
        def population_values(args, thetas, idx, valid):
            def member(th):
                value, out = problem.hard(args, problem.param.gains(th), idx, valid)
                return value, problem.failed(out, valid)

            return jax.vmap(member)(thetas)

        return population_values

    return build


def _run_es(
    problem, theta, opt, temps, batch, steps, train_runs, gradient, population, sigma,
    monitor, callback, seed,
):  # fmt: skip
    per_member = max(batch // (2 * population), 1)
    rng = np.random.default_rng(seed)

    n = len(theta)
    idx, valid = problem.padded(train_indices(0, per_member, train_runs))
    members = np.zeros((2 * population + 1, n))
    fn, compile_s = problem.compiled("es", _population(problem), problem.args, members, idx, valid)
    update, state, update_s = _compiled_update(opt, theta)
    compile_s += update_s
    history, wall = [], 0.0
    for s in range(steps):
        idx, valid = problem.padded(train_indices(s, per_member, train_runs))
        eps = rng.standard_normal((population, n))
        t0 = time.perf_counter()
        members = np.concatenate([theta[None], theta + sigma * eps, theta - sigma * eps])
        values, failed = (np.asarray(x) for x in fn(problem.args, members, idx, valid))
        scores = lexicographic_scores(values[1:], failed[1:])
        plus, minus = scores[:population], scores[population:]
        grad = np.sum((plus - minus)[:, None] * eps, axis=0) / (2.0 * sigma * population)
        stepped, state = update(grad, state, theta)
        stepped = np.asarray(stepped)
        wall += time.perf_counter() - t0
        runs = (s + 1) * per_member * 2 * population
        rec = _record(problem, s, values[0], theta, None, runs, wall)
        theta = stepped
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
        if rec.get("heldout_failed"):
            line += f" ({rec['heldout_failed']} failed)"
    if rec.get("nonfinite_gradient"):
        line += f"  gradient: {rec['nonfinite_gradient']} non-finite component(s) taken as 0"
    return line + f"  ({rec['wall_s']:.1f} s)"


def _run_cma(
    problem, theta, opt, temps, batch, steps, train_runs, gradient, population, sigma,
    monitor, callback, seed,
):  # fmt: skip
    import cma

    per_member = max(batch // (2 * population), 1)
    n = len(theta)

    idx, valid = problem.padded(train_indices(0, per_member, train_runs))
    members = np.zeros((2 * population + 1, n))
    fn, compile_s = problem.compiled("es", _population(problem), problem.args, members, idx, valid)
    options = {"popsize": 2 * population, "seed": seed + 1, "verbose": -9}
    es = cma.CMAEvolutionStrategy(np.asarray(theta, float), sigma, options)
    history, wall = [], 0.0
    for s in range(steps):
        idx, valid = problem.padded(train_indices(s, per_member, train_runs))
        t0 = time.perf_counter()
        mean = np.array(es.mean)
        candidates = es.ask()
        members = np.concatenate([mean[None], np.asarray(candidates)])
        values, failed = (np.asarray(x) for x in fn(problem.args, members, idx, valid))
        # fewer failed runs rank first, a member with no ok run last (CMA-ES ranks: any
        # scores in that order give the same generation)
        scores = lexicographic_scores(values[1:], failed[1:])
        es.tell(candidates, [float(v) if np.isfinite(v) else 1e300 for v in scores])
        wall += time.perf_counter() - t0
        runs = (s + 1) * per_member * 2 * population
        rec = _record(problem, s, values[0], mean, None, runs, wall)
        _monitor(problem, rec, np.array(es.mean), s, steps, monitor)
        history.append(rec)
        if callback:
            callback(rec)
    return history, np.array(es.mean), compile_s, wall
