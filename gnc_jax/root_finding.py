"""Bounded regula falsi with a warm start: the bank-angle corrector of seed 003 §3.2.

The corrector of a numerical predictor-corrector entry guidance solves S(sigma) = 0 for the bank
angle, where S is the range error predicted by integrating the trajectory. Seed 003 (eqs. 11-15)
does it in three stages, each costing one prediction per evaluation of S:

1. test the previous cycle's solution x_prev: if |S(x_prev)| < tol keep it (eq. 14 preamble);
2. bracket: step away from x_prev by n * step, n = 1, 2, ... (eq. 15) until S changes sign;
3. regula falsi (eqs. 12-13) on the bracket, keeping the sub-interval with the sign change.

Given the slope dS/dx of the previous cycle, the first bracketing candidate is instead the
secant (Newton) point x_prev - S(x_prev) / slope: from one cycle to the next the root moves
little and S is nearly linear there, so that candidate is usually within the tolerance or
brackets the root tightly (two predictions per cycle instead of about four).

To run under ``vmap`` every stage is a fixed-length ``lax.scan`` whose iterations are masked
once the answer is known (a batch of guidance cycles then costs the same as its slowest member);
``n_evals_early_exit`` counts the evaluations a sequential early-exit loop would have made,
which is the paper's "predictions per cycle" (seed 003 Table 3).
"""

import enum
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ._types import Array, Bool, Int, Scalar


class RootStatus(enum.IntEnum):
    """Outcome of `bounded_regula_falsi` (like diffrax's RESULTS)."""

    ok = 0  # |f(x)| < tol
    not_bracketed = 1  # no sign change between x_prev and the bound (or within n_bracket steps)
    no_convergence = 2  # bracketed, but |f| >= tol after n_iter regula-falsi iterations


class RegulaFalsiResult(NamedTuple):
    """Result of `bounded_regula_falsi`.

    Attributes:
        x: the root if converged, else the evaluated point with the smallest |f|.
        f_x: f(x).
        converged: |f_x| < tol.
        n_evals_early_exit: evaluations of ``fun`` an early-exit loop would have made (>= 1).
        n_evals_total: evaluations actually made, 1 + n_bracket + n_iter (the fixed cost).
        status: a `RootStatus` code.
        slope: df/dx from the last two evaluations (the secant through them), or the slope
            given to the solve when it made fewer than two: the next solve's ``slope``.
    """

    x: Scalar
    f_x: Scalar
    converged: Bool[Array, ""]
    n_evals_early_exit: Int[Array, ""]
    n_evals_total: Int[Array, ""]
    status: Int[Array, ""]
    aux: Any = None
    cost: Any = None
    slope: Any = None


class _Best(NamedTuple):
    x: Scalar
    f: Scalar
    aux: Any


class _Tally(NamedTuple):
    """What every stage carries on: convergence, the best point so far, the evaluations an
    early-exit loop would have made, the summed cost of the evaluations, and the last two
    evaluated points (x, f) for the slope."""

    converged: Bool[Array, ""]
    best: _Best
    n_evals: Int[Array, ""]
    cost: Any
    last: tuple[Scalar, Scalar]
    previous: tuple[Scalar, Scalar]


class _Bracketing(NamedTuple):
    """Loop state of the bracketing search (eqs. 14-15)."""

    x_same: Scalar  # last candidate with the sign of f(x_prev)
    f_same: Scalar
    x_before: Scalar  # the one before it (NaN: none), for the secant
    f_before: Scalar
    x_other: Scalar  # first candidate with the other sign
    f_other: Scalar
    x_next: Scalar  # next candidate (secant mode)
    found: Bool[Array, ""]  # a sign change was found
    stop: Bool[Array, ""]  # the bound was reached without one
    tally: _Tally


class _Falsi(NamedTuple):
    """Loop state of the regula-falsi refinement (eqs. 12-13) on the bracket x_a < x_b."""

    x_a: Scalar
    f_a: Scalar
    x_b: Scalar
    f_b: Scalar
    last_kept: Int[Array, ""]  # +1 if b was the endpoint kept last, -1 if a, 0 at first
    tally: _Tally


Objective = Callable[[Scalar, Bool[Array, ""]], tuple[Scalar, Any, Any]]


def _keep_best(best: _Best, x: Scalar, f: Scalar, aux, active: Bool[Array, ""]) -> _Best:
    better = active & (jnp.abs(f) < jnp.abs(best.f))
    return _Best(
        jnp.where(better, x, best.x),
        jnp.where(better, f, best.f),
        jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), aux, best.aux),
    )


def _evaluate(objective: Objective, x, active, tol, tally: _Tally):
    """``f(x)``, whether it is within ``tol`` (for an ``active`` evaluation), and the tally
    updated with it."""
    f, aux, cost = objective(x, active)
    hit = active & (jnp.abs(f) < tol)
    tally = _Tally(
        converged=tally.converged | hit,
        best=_keep_best(tally.best, x, f, aux, active),
        n_evals=tally.n_evals + active,
        cost=tally.cost + cost,
        last=(jnp.where(active, x, tally.last[0]), jnp.where(active, f, tally.last[1])),
        previous=tuple(jnp.where(active, a, b) for a, b in zip(tally.last, tally.previous)),
    )
    return f, hit, tally


def _bracket(
    objective: Objective,
    x0,
    f0,
    step,
    lower,
    upper,
    tol,
    n_bracket,
    up,
    tally,
    slope=None,
    decreasing=True,
):
    """Candidates x_n = clip(x0 +/- n step), n = 1..n_bracket (eq. 15), until f changes sign.

    With a usable ``slope`` (finite, of the ``decreasing`` sign: the secant mode), each
    candidate is instead the secant point from the last candidate on f's side: x - f(x) / s,
    with s the given slope for the first and the secant through the last two such candidates
    after it, or a step of eq. 15 from the last candidate when that secant is not usable.
    Secant steps are bounded by the reach of eq. 15, n_bracket step. An unusable slope on
    entry (NaN: unknown) gives the candidates of eq. 15.

    Returns the bracket (x_a, f_a, x_b, f_b) with x_a < x_b -- [last candidate with the sign
    of f(x0), first with the other sign] -- whether one was found, and the tally."""
    bound = jnp.where(up, upper, lower)
    direction = jnp.where(up, 1.0, -1.0)
    monotone = 1.0 if decreasing else -1.0
    reach = n_bracket * step

    def usable(s):
        return (monotone * s < 0.0) & jnp.isfinite(s)

    def secant_from(x, f, s):
        delta = jnp.clip(-f / jnp.where(usable(s), s, -monotone), -reach, reach)
        return jnp.where(usable(s), x + delta, x + direction * step)

    # secant mode only with a usable slope on entry; an unknown one: eq. 15 throughout
    secant_mode = jnp.asarray(False) if slope is None else usable(slope)

    def bracket_step(s: _Bracketing, n):
        active = ~(s.found | s.stop | s.tally.converged)
        x_n = jnp.where(secant_mode, s.x_next, x0 + direction * n * step)
        x_n = jnp.where(up, jnp.minimum(x_n, upper), jnp.maximum(x_n, lower))
        f_n, converged_n, tally = _evaluate(objective, x_n, active, tol, s.tally)
        crossed = active & ~converged_n & (jnp.sign(f_n) != jnp.sign(f0))
        same = active & ~converged_n & ~crossed
        x_same, f_same = jnp.where(same, x_n, s.x_same), jnp.where(same, f_n, s.f_same)
        x_before = jnp.where(same, s.x_same, s.x_before)
        f_before = jnp.where(same, s.f_same, s.f_before)
        x_next = s.x_next
        if slope is not None:
            two = x_same != x_before
            s_now = (f_same - f_before) / jnp.where(two, x_same - x_before, 1.0)
            x_next = secant_from(x_same, f_same, jnp.where(two, s_now, jnp.nan))
        return _Bracketing(
            x_same=x_same,
            f_same=f_same,
            x_before=x_before,
            f_before=f_before,
            x_other=jnp.where(crossed, x_n, s.x_other),
            f_other=jnp.where(crossed, f_n, s.f_other),
            x_next=x_next,
            found=s.found | crossed,
            stop=s.stop | (same & (x_n == bound)),
            tally=tally,
        ), None

    nan = jnp.full_like(x0, jnp.nan)
    init = _Bracketing(
        x_same=x0,
        f_same=f0,
        x_before=nan,
        f_before=nan,
        x_other=x0,
        f_other=f0,
        x_next=x0 if slope is None else secant_from(x0, f0, slope),
        found=jnp.asarray(False),
        stop=jnp.where(up, x0 >= upper, x0 <= lower),
        tally=tally,
    )
    steps = jnp.arange(1, n_bracket + 1, dtype=float)
    s, _ = jax.lax.scan(bracket_step, init, steps)
    swap = s.x_other < s.x_same
    x_a, f_a = jnp.where(swap, s.x_other, s.x_same), jnp.where(swap, s.f_other, s.f_same)
    x_b, f_b = jnp.where(swap, s.x_same, s.x_other), jnp.where(swap, s.f_same, s.f_other)
    # the candidate that crossed is the last evaluated: side a (+1) if it is the lower end
    return (x_a, f_a, x_b, f_b), s.found, s.tally, jnp.where(swap, 1, -1)


def _refine(
    objective: Objective,
    bracket,
    bracketed,
    tol,
    n_iter,
    illinois,
    tally,
    anderson_bjorck=False,
    last_kept=0,
) -> _Tally:
    """Regula falsi (eqs. 12-13) on the bracket, with the Illinois rule if ``illinois`` (the
    Anderson-Bjorck factor instead of 1/2 if ``anderson_bjorck``); ``last_kept``: the side
    of the bracket evaluated last (+1 a, -1 b, 0 unknown)."""

    def falsi_step(s: _Falsi, _):
        active = bracketed & ~s.tally.converged
        # Guarded so masked iterations (no bracket, f_a == f_b) give no NaN, nor NaN gradients.
        ok = active & (s.f_b != s.f_a)
        denominator = jnp.where(ok, s.f_b - s.f_a, 1.0)
        x_c = jnp.where(ok, (s.x_a * s.f_b - s.x_b * s.f_a) / denominator, s.x_a)
        x_c = jnp.clip(x_c, s.x_a, s.x_b)  # rounding must not leave the bracket
        f_c, converged_c, tally = _evaluate(objective, x_c, active, tol, s.tally)
        replace_a = active & ~converged_c & (jnp.sign(f_c) == jnp.sign(s.f_a))
        replace_b = active & ~converged_c & ~replace_a
        kept = jnp.where(replace_a, 1, jnp.where(replace_b, -1, 0))
        halve = illinois & (kept != 0) & (kept == s.last_kept)
        if anderson_bjorck:
            # m = 1 - f(c) / f(replaced end), or 1/2 when that is not in (0, 1)
            f_old = jnp.where(replace_a, s.f_a, s.f_b)
            m = 1.0 - f_c / jnp.where(f_old != 0.0, f_old, 1.0)
            factor = jnp.where((m > 0.0) & (m < 1.0), m, 0.5)
        else:
            factor = 0.5
        return _Falsi(
            x_a=jnp.where(replace_a, x_c, s.x_a),
            f_a=jnp.where(replace_a, f_c, jnp.where(halve & replace_b, factor * s.f_a, s.f_a)),
            x_b=jnp.where(replace_b, x_c, s.x_b),
            f_b=jnp.where(replace_b, f_c, jnp.where(halve & replace_a, factor * s.f_b, s.f_b)),
            last_kept=jnp.where(active, kept, s.last_kept),
            tally=tally,
        ), None

    x_a, f_a, x_b, f_b = bracket
    init = _Falsi(x_a=x_a, f_a=f_a, x_b=x_b, f_b=f_b, last_kept=jnp.asarray(last_kept), tally=tally)
    s, _ = jax.lax.scan(falsi_step, init, None, length=n_iter)
    return s.tally


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
    """
    lower = jnp.asarray(lower, dtype=float)
    upper = jnp.asarray(upper, dtype=float)
    x0 = jnp.clip(jnp.asarray(x_prev, dtype=float), lower, upper)
    enabled = jnp.asarray(enabled)

    f0, aux0, cost0 = objective(x0, enabled)
    tally = _Tally(
        converged=(jnp.abs(f0) < tol) | ~enabled,
        best=_Best(x0, f0, aux0),
        n_evals=enabled.astype(int),
        cost=cost0,
        last=(x0, f0),
        previous=(x0, f0),
    )
    sign = 1.0 if decreasing else -1.0
    up = sign * f0 >= 0.0
    if slope is not None:
        slope = jnp.asarray(slope, dtype=float)
    bracket, bracketed, tally, last_side = _bracket(
        objective, x0, f0, step, lower, upper, tol, n_bracket, up, tally, slope, decreasing
    )
    tally = _refine(
        objective,
        bracket,
        bracketed,
        tol,
        n_iter,
        illinois,
        tally,
        anderson_bjorck,
        last_side if anderson_bjorck else 0,
    )
    (x_1, f_1), (x_2, f_2) = tally.last, tally.previous
    two = x_1 != x_2
    new_slope = jnp.where(two, (f_1 - f_2) / jnp.where(two, x_1 - x_2, 1.0), jnp.nan)
    if slope is not None:
        new_slope = jnp.where(two, new_slope, slope)

    status = jnp.where(
        tally.converged,
        RootStatus.ok,
        jnp.where(bracketed, RootStatus.no_convergence, RootStatus.not_bracketed),
    )
    return RegulaFalsiResult(
        x=tally.best.x,
        f_x=tally.best.f,
        converged=tally.converged,
        n_evals_early_exit=tally.n_evals,
        n_evals_total=jnp.asarray(1 + n_bracket + n_iter),
        status=status,
        aux=tally.best.aux,
        cost=tally.cost,
        slope=new_slope,
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
