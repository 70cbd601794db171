"""The solve driven by a fixed-length ``lax.scan``: :func:`bounded_regula_falsi` and
:func:`bounded_regula_falsi_with_aux`, and :func:`regula_falsi`, the machine of their
arguments."""

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Scalar
from .machine import RegulaFalsi
from .result import RegulaFalsiResult

Objective = Callable[[Scalar, Bool[Array, ""]], tuple[Scalar, Any, Any]]


def _zeros_like(tree):
    """Zeros of the shapes and dtypes of ``tree`` (arrays or ``jax.ShapeDtypeStruct``)."""
    return jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), tree)


def bounded_regula_falsi_with_aux(
    objective: Objective,
    x_prev: Scalar,
    step: Scalar,
    lower: Scalar,
    upper: Scalar,
    tol: Scalar,
    n_bracket: int,
    n_iter: int,
    illinois: bool = True,
    decreasing: bool = True,
    enabled=True,
    slope=None,
    anderson_bjorck=False,
) -> RegulaFalsiResult:
    """:func:`bounded_regula_falsi` of an objective ``objective(x, active) -> (f, aux, cost)``.

    ``active`` says whether the evaluation is used: an expensive objective (a trajectory
    prediction in a ``while_loop``) can skip masked evaluations, so under ``vmap`` the batch
    pays only for the runs that still iterate. The result's ``aux`` is that of the returned x
    (the evaluated point with the smallest |f|), so a caller gets, say, the whole prediction of
    its solution without evaluating it again; its ``cost`` is the sum over every evaluation
    (e.g. integration steps actually taken). ``aux`` may be ``None``; ``cost`` must add up.
    Other arguments as :func:`bounded_regula_falsi`.

    The solve is the :class:`RegulaFalsi` machine driven by a ``lax.scan`` of
    1 + n_bracket + n_iter slots, each evaluating the pending proposal of every run: a run's
    k-th evaluation is in slot k whatever its stage.
    """
    solver = regula_falsi(
        step,
        lower,
        upper,
        tol,
        n_bracket,
        n_iter,
        illinois,
        decreasing,
        enabled,
        slope,
        anderson_bjorck,
    )
    x0 = jnp.clip(jnp.asarray(x_prev, dtype=float), solver.lower, solver.upper)
    _, aux, cost = jax.eval_shape(objective, x0, solver.enabled)

    def slot(s, _):
        x, active = solver.propose(s)
        f, aux, cost = objective(x, active)
        return solver.absorb(s, x, f, aux, cost), None

    s, _ = jax.lax.scan(
        slot, solver.init(x0, _zeros_like(aux), _zeros_like(cost)), None, solver.n_evals_total
    )
    return solver.result(s)


def regula_falsi(
    step,
    lower,
    upper,
    tol,
    n_bracket: int,
    n_iter: int,
    illinois: bool = True,
    decreasing: bool = True,
    enabled=True,
    slope=None,
    anderson_bjorck=False,
) -> RegulaFalsi:
    """The :class:`RegulaFalsi` machine of the arguments of :func:`bounded_regula_falsi`."""
    return RegulaFalsi(
        step=jnp.asarray(step, dtype=float),
        lower=jnp.asarray(lower, dtype=float),
        upper=jnp.asarray(upper, dtype=float),
        tol=jnp.asarray(tol, dtype=float),
        enabled=jnp.asarray(enabled),
        slope=None if slope is None else jnp.asarray(slope, dtype=float),
        n_bracket=n_bracket,
        n_iter=n_iter,
        illinois=illinois,
        decreasing=decreasing,
        anderson_bjorck=anderson_bjorck,
    )


def bounded_regula_falsi(
    fun: Callable[[Scalar], Scalar],
    x_prev: Scalar,
    step: Scalar,
    lower: Scalar,
    upper: Scalar,
    tol: Scalar,
    n_bracket: int,
    n_iter: int,
    illinois: bool = True,
    decreasing: bool = True,
    enabled=True,
    slope=None,
    anderson_bjorck=False,
) -> RegulaFalsiResult:
    """Solve fun(x) = 0 in [lower, upper], warm-started at ``x_prev`` (seed 003 eqs. 11-15).

    Args:
        fun: pure scalar function of x (a closure over vmapped data is fine); see
            :func:`bounded_regula_falsi_with_aux` for an objective with an auxiliary result,
            a cost, or that skips masked evaluations.
        x_prev: previous solution, the first point tested (clipped into [lower, upper]).
        step: bracketing step Delta sigma > 0 (eq. 15).
        lower, upper: bounds of x; bracketing candidates are clipped to them.
        tol: acceptance threshold on |fun(x)| (same units as fun).
        n_bracket: bracketing steps n = 1..n_bracket (static: fixes the loop length).
        n_iter: regula-falsi iterations (static).
        illinois: halve the stored f of an endpoint kept twice in a row (Dowell & Jarratt 1971).
            Plain regula falsi (eq. 13) keeps one endpoint forever on a convex or concave f
            and converges only linearly; the Illinois rule restores superlinear convergence at
            no extra evaluation. False reproduces eq. 13 literally.
        decreasing: monotonicity assumption that picks the bracketing direction (eqs. 14-15).
            True (the seed's case: more bank, less range): f(x_prev) >= 0 steps up, f < 0
            steps down. False: the opposite.
        enabled: (traced bool) False turns the whole solve into no-op evaluations (counted as
            none, the result is x_prev clipped).
        slope: an estimate of df/dx near the root (the previous solve's ``result.slope``), or
            None (eq. 15). A finite slope of the ``decreasing`` sign makes the bracketing a
            secant search: the first candidate is the secant point x_prev - f(x_prev) / slope,
            the next ones secant points through the last two candidates, each step bounded by
            n_bracket * step (a step of eq. 15 when a secant has not that sign). NaN or the
            wrong sign: the candidates of eq. 15.
        anderson_bjorck: with ``illinois``, scale the stored f of an endpoint kept twice in a
            row by m = 1 - f(x_c) / f(replaced endpoint) (1/2 when m is not in (0, 1)) instead
            of 1/2 (Anderson & Bjorck 1973): still regula falsi on a bracket, but superlinear
            (order about 1.7) on the convex range errors of a skip entry, where the Illinois
            rule gains a factor of about 3 per iteration; the rule is then applied from the
            first iteration, the bracket's last evaluated end counting as the last replaced.

    Bracketing: candidates x_n = clip(x_prev +/- n step) are tried until f changes sign; the
    bracket is then [last candidate with the sign of f(x_prev), first with the other sign] --
    the seed keeps x_prev as the fixed end (eq. 14); the tighter bracket is also valid and
    saves iterations. If the bound is reached (or n_bracket steps pass) without a sign change,
    the status is ``not_bracketed`` and x is the evaluated point with the smallest |f|, which
    for a monotone f is the bound: the guidance saturates.

    Regula falsi (eq. 12): x_c = (x_a f(x_b) - x_b f(x_a)) / (f(x_b) - f(x_a)), x_a < x_b,
    replacing the endpoint whose f has the sign of f(x_c) (eq. 13), until |f(x_c)| < tol.
    """

    def objective(x, active):
        return fun(x), None, jnp.zeros(())

    return bounded_regula_falsi_with_aux(
        objective,
        x_prev,
        step,
        lower,
        upper,
        tol,
        n_bracket,
        n_iter,
        illinois,
        decreasing,
        enabled,
        slope,
        anderson_bjorck,
    )
