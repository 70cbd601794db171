"""Bounded regula falsi with a warm start: the bank-angle corrector of seed 003 §3.2 (SPEC §8).

The corrector of a numerical predictor-corrector entry guidance solves S(sigma) = 0 for the bank
angle, where S is the range error predicted by integrating the trajectory. Seed 003 (eqs. 11-15)
does it in three stages, each costing one prediction per evaluation of S:

1. test the previous cycle's solution x_prev: if |S(x_prev)| < tol keep it (eq. 14 preamble);
2. bracket: step away from x_prev by n * step, n = 1, 2, ... (eq. 15) until S changes sign;
3. regula falsi (eqs. 12-13) on the bracket, keeping the sub-interval with the sign change.

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
    """

    x: Scalar
    f_x: Scalar
    converged: Bool[Array, ""]
    n_evals_early_exit: Int[Array, ""]
    n_evals_total: Int[Array, ""]
    status: Int[Array, ""]
    aux: Any = None
    cost: Any = None


class _Best(NamedTuple):
    x: Scalar
    f: Scalar
    aux: Any


def _keep_best(best: _Best, x: Scalar, f: Scalar, aux, active: Bool[Array, ""]) -> _Best:
    better = active & (jnp.abs(f) < jnp.abs(best.f))
    return _Best(
        jnp.where(better, x, best.x),
        jnp.where(better, f, best.f),
        jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), aux, best.aux),
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
    pass_active: bool = False,
    has_aux: bool = False,
    has_cost: bool = False,
) -> RegulaFalsiResult:
    """Solve fun(x) = 0 in [lower, upper], warm-started at ``x_prev`` (seed 003 eqs. 11-15).

    Args:
        fun: pure scalar function of x (a closure over vmapped data is fine).
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
        enabled: (traced bool) False turns the whole solve into no-op evaluations: under
            ``vmap`` a run that does not need a solution this cycle costs nothing when ``fun``
            honours ``active`` (see ``pass_active``).
        pass_active: call ``fun(x, active)`` where ``active`` says whether the result is
            used; an expensive ``fun`` (a trajectory prediction in a ``while_loop``) can then
            skip masked evaluations, so under ``vmap`` the batch pays only for the runs
            that still iterate.
        has_aux: ``fun`` returns ``(f, aux)``; the result's ``aux`` is that of the returned x
            (the evaluated point with the smallest |f|), so a caller gets, say, the whole
            prediction of its solution without evaluating it again.
        has_cost: ``fun`` returns ``(f, aux, cost)`` (requires ``has_aux``); the result's
            ``cost`` is the sum over every evaluation (e.g. integration steps actually taken).

    Bracketing: candidates x_n = clip(x_prev +/- n step) are tried until f changes sign; the
    bracket is then [last candidate with the sign of f(x_prev), first with the other sign] --
    the seed keeps x_prev as the fixed end (eq. 14); the tighter bracket is also valid and
    saves iterations. If the bound is reached (or n_bracket steps pass) without a sign change,
    the status is ``not_bracketed`` and x is the evaluated point with the smallest |f|, which
    for a monotone f is the bound: the guidance saturates.

    Regula falsi (eq. 12): x_c = (x_a f(x_b) - x_b f(x_a)) / (f(x_b) - f(x_a)), x_a < x_b,
    replacing the endpoint whose f has the sign of f(x_c) (eq. 13), until |f(x_c)| < tol.
    """
    sign = 1.0 if decreasing else -1.0
    lower = jnp.asarray(lower, dtype=float)
    upper = jnp.asarray(upper, dtype=float)
    x0 = jnp.clip(jnp.asarray(x_prev, dtype=float), lower, upper)
    enabled = jnp.asarray(enabled)

    def call(x, active):
        out = fun(x, active) if pass_active else fun(x)
        if has_cost:
            f, aux, c = out
            return f, aux, c
        return (out + (jnp.zeros(()),)) if has_aux else (out, None, jnp.zeros(()))

    f0, aux0, cost0 = call(x0, enabled)
    converged = (jnp.abs(f0) < tol) | ~enabled
    best = _Best(x0, f0, aux0)
    n_evals = enabled.astype(int)
    cost = cost0

    # --- bracketing (eqs. 14-15) ---
    up = sign * f0 >= 0.0
    bound = jnp.where(up, upper, lower)
    at_bound = jnp.where(up, x0 >= upper, x0 <= lower)

    def bracket_step(carry, n):
        x_same, f_same, x_other, f_other, found, stop, converged, best, n_evals, cost = carry
        active = ~(found | stop | converged)
        x_n = jnp.where(up, jnp.minimum(x0 + n * step, upper), jnp.maximum(x0 - n * step, lower))
        f_n, aux_n, cost_n = call(x_n, active)
        n_evals = n_evals + active
        converged_n = active & (jnp.abs(f_n) < tol)
        crossed = active & ~converged_n & (jnp.sign(f_n) != jnp.sign(f0))
        same = active & ~converged_n & ~crossed
        best = _keep_best(best, x_n, f_n, aux_n, active)
        return (
            jnp.where(same, x_n, x_same),
            jnp.where(same, f_n, f_same),
            jnp.where(crossed, x_n, x_other),
            jnp.where(crossed, f_n, f_other),
            found | crossed,
            stop | (same & (x_n == bound)),
            converged | converged_n,
            best,
            n_evals,
            cost + cost_n,
        ), None

    init = (x0, f0, x0, f0, jnp.asarray(False), at_bound, converged, best, n_evals, cost)
    steps = jnp.arange(1, n_bracket + 1, dtype=float)
    (x_same, f_same, x_other, f_other, bracketed, _, converged, best, n_evals, cost), _ = (
        jax.lax.scan(bracket_step, init, steps)
    )

    # --- regula falsi (eqs. 11-13) on x_a < x_b ---
    swap = x_other < x_same
    x_a, f_a = jnp.where(swap, x_other, x_same), jnp.where(swap, f_other, f_same)
    x_b, f_b = jnp.where(swap, x_same, x_other), jnp.where(swap, f_same, f_other)

    def falsi_step(carry, _):
        x_a, f_a, x_b, f_b, last_kept, converged, best, n_evals, cost = carry
        active = bracketed & ~converged
        # Guarded so masked iterations (no bracket, f_a == f_b) give no NaN, nor NaN gradients.
        ok = active & (f_b != f_a)
        denominator = jnp.where(ok, f_b - f_a, 1.0)
        x_c = jnp.where(ok, (x_a * f_b - x_b * f_a) / denominator, x_a)
        x_c = jnp.clip(x_c, x_a, x_b)  # rounding must not leave the bracket
        f_c, aux_c, cost_c = call(x_c, active)
        n_evals = n_evals + active
        converged_c = active & (jnp.abs(f_c) < tol)
        replace_a = active & ~converged_c & (jnp.sign(f_c) == jnp.sign(f_a))
        replace_b = active & ~converged_c & ~replace_a
        best = _keep_best(best, x_c, f_c, aux_c, active)
        # last_kept: +1 if b was the endpoint kept last time, -1 if a, 0 before the first step.
        kept = jnp.where(replace_a, 1, jnp.where(replace_b, -1, 0))
        halve = illinois & (kept != 0) & (kept == last_kept)
        f_a_new = jnp.where(replace_a, f_c, jnp.where(halve & replace_b, 0.5 * f_a, f_a))
        f_b_new = jnp.where(replace_b, f_c, jnp.where(halve & replace_a, 0.5 * f_b, f_b))
        return (
            jnp.where(replace_a, x_c, x_a),
            f_a_new,
            jnp.where(replace_b, x_c, x_b),
            f_b_new,
            jnp.where(active, kept, last_kept),
            converged | converged_c,
            best,
            n_evals,
            cost + cost_c,
        ), None

    init = (x_a, f_a, x_b, f_b, jnp.asarray(0), converged, best, n_evals, cost)
    (*_, converged, best, n_evals, cost), _ = jax.lax.scan(falsi_step, init, None, length=n_iter)

    status = jnp.where(
        converged,
        RootStatus.ok,
        jnp.where(bracketed, RootStatus.no_convergence, RootStatus.not_bracketed),
    )
    return RegulaFalsiResult(
        x=best.x,
        f_x=best.f,
        converged=converged,
        n_evals_early_exit=n_evals,
        n_evals_total=jnp.asarray(1 + n_bracket + n_iter),
        status=status,
        aux=best.aux,
        cost=cost,
    )
