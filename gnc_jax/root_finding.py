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

To run under ``vmap`` the solve is a state machine (:class:`RegulaFalsi`) that proposes one x
at a time and absorbs its f: :func:`bounded_regula_falsi` drives it with a fixed-length
``lax.scan`` whose slots are masked once a run's answer is known (a batch of guidance cycles
then costs the same as its slowest member); a caller with evaluations of variable length can
drive it with its own loop (see the skip-entry law's corrector,
:func:`gnc_jax.guidance.entry.corrector.correct`).
``n_evals_early_exit`` counts the evaluations a sequential early-exit loop would have made,
which is the paper's "predictions per cycle" (seed 003 Table 3).
"""

import enum
from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
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


class _Solve(NamedTuple):
    """State of one solve between evaluations (see :class:`RegulaFalsi`).

    The stage says what the next evaluation is: -1 the warm start x0, 0 the bracketing
    candidate ``count + 1`` (eqs. 14-15), 1 the regula-falsi iteration ``count + 1`` on the
    bracket x_a < x_b (eqs. 12-13), 2 none (done)."""

    stage: Int[Array, ""]
    count: Int[Array, ""]  # evaluations made in this stage
    x0: Scalar  # the warm start and its f
    f0: Scalar
    up: Bool[Array, ""]  # the bracketing steps up (towards ``upper``)
    x_same: Scalar  # last candidate with the sign of f(x0)
    f_same: Scalar
    x_before: Scalar  # the one before it (NaN: none), for the secant
    f_before: Scalar
    x_other: Scalar  # first candidate with the other sign
    f_other: Scalar
    x_next: Scalar  # next candidate (secant mode)
    found: Bool[Array, ""]  # a sign change was found
    stop: Bool[Array, ""]  # the bound was reached without one
    x_a: Scalar
    f_a: Scalar
    x_b: Scalar
    f_b: Scalar
    last_kept: Int[Array, ""]  # +1 if b was the endpoint kept last, -1 if a, 0 at first
    tally: _Tally


Objective = Callable[[Scalar, Bool[Array, ""]], tuple[Scalar, Any, Any]]


def _keep_best(best: _Best, x: Scalar, f: Scalar, aux) -> _Best:
    """The evaluated point of smallest |f|; of equal ones the later. On a plateau of f (a
    skip-out predicted for every candidate: the same overshoot) the later candidate is the
    one farthest along the bracketing direction, towards the bound a monotone f would
    saturate at, where the first one would leave the command where it was."""
    better = jnp.abs(f) <= jnp.abs(best.f)
    return _Best(
        jnp.where(better, x, best.x),
        jnp.where(better, f, best.f),
        jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), aux, best.aux),
    )


def _select(pick, new, old):
    return jax.tree_util.tree_map(lambda a, b: jnp.where(pick, a, b), new, old)


def _zeros_like(tree):
    """Zeros of the shapes and dtypes of ``tree`` (arrays or ``jax.ShapeDtypeStruct``)."""
    return jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), tree)


class RegulaFalsi(eqx.Module):
    """The bounded regula falsi of :func:`bounded_regula_falsi` as a state machine, one
    evaluation at a time: ``init`` the state, then ``propose`` the next x (and whether it is
    to be evaluated), ``absorb`` its f, until the stage is 2 (done; a masked proposal), and
    ``result``. The solve is the same whoever drives it: :func:`bounded_regula_falsi_with_aux`
    evaluates one proposal per slot of a fixed ``lax.scan``; a caller whose evaluations take a
    variable number of loop steps (a trajectory prediction) can advance every run of a
    ``vmap`` batch to its next proposal as soon as its own evaluation finishes, so that no run
    waits for the slowest of each slot. Arguments as :func:`bounded_regula_falsi`."""

    step: Scalar
    lower: Scalar
    upper: Scalar
    tol: Scalar
    enabled: Bool[Array, ""]
    slope: Scalar | None
    n_bracket: int = eqx.field(static=True)
    n_iter: int = eqx.field(static=True)
    illinois: bool = eqx.field(static=True, default=True)
    decreasing: bool = eqx.field(static=True, default=True)
    anderson_bjorck: bool = eqx.field(static=True, default=False)

    @property
    def n_evals_total(self) -> int:
        """Evaluations of a solve that uses every slot: 1 + n_bracket + n_iter."""
        return 1 + self.n_bracket + self.n_iter

    def _usable(self, s):
        monotone = 1.0 if self.decreasing else -1.0
        return (monotone * s < 0.0) & jnp.isfinite(s)

    def _secant_from(self, x, f, s, direction):
        """Secant point from (x, f) on the slope s, bounded by the reach of eq. 15,
        n_bracket step; a step of eq. 15 when s is not usable."""
        monotone = 1.0 if self.decreasing else -1.0
        reach = self.n_bracket * self.step
        delta = jnp.clip(-f / jnp.where(self._usable(s), s, -monotone), -reach, reach)
        return jnp.where(self._usable(s), x + delta, x + direction * self.step)

    def init(self, x_prev, aux, cost) -> _Solve:
        """The state before the first evaluation, at ``x_prev`` clipped into the bounds.
        ``aux`` and ``cost``: any values of the objective's (their structure)."""
        x0 = jnp.clip(jnp.asarray(x_prev, dtype=float), self.lower, self.upper)
        zero = jnp.zeros_like(x0)
        nan = jnp.full_like(x0, jnp.nan)
        false = jnp.asarray(False)
        tally = _Tally(
            converged=false,
            best=_Best(x0, nan, aux),
            n_evals=jnp.zeros((), int),
            cost=jax.tree_util.tree_map(jnp.zeros_like, cost),
            last=(x0, nan),
            previous=(x0, nan),
        )
        return _Solve(
            stage=jnp.asarray(-1),
            count=jnp.zeros((), int),
            x0=x0,
            f0=nan,
            up=false,
            x_same=x0,
            f_same=nan,
            x_before=nan,
            f_before=nan,
            x_other=x0,
            f_other=nan,
            x_next=x0,
            found=false,
            stop=false,
            x_a=x0,
            f_a=zero,
            x_b=x0,
            f_b=zero,
            last_kept=jnp.zeros((), int),
            tally=tally,
        )

    def done(self, s: _Solve) -> Bool[Array, ""]:
        return s.stage == 2

    def propose(self, s: _Solve):
        """The next x to evaluate, and whether the evaluation is used (``active``): the
        solve is neither done nor disabled."""
        direction = jnp.where(s.up, 1.0, -1.0)
        n = (s.count + 1).astype(float)
        x_n = jnp.where(self._secant_mode(), s.x_next, s.x0 + direction * n * self.step)
        x_n = jnp.where(s.up, jnp.minimum(x_n, self.upper), jnp.maximum(x_n, self.lower))
        # Guarded so that a bracket with f_a == f_b (or a masked proposal) gives no NaN, nor
        # NaN gradients.
        ok = s.f_b != s.f_a
        denominator = jnp.where(ok, s.f_b - s.f_a, 1.0)
        x_c = jnp.where(ok, (s.x_a * s.f_b - s.x_b * s.f_a) / denominator, s.x_a)
        x_c = jnp.clip(x_c, s.x_a, s.x_b)  # rounding must not leave the bracket
        x = jnp.where(s.stage == 0, x_n, jnp.where(s.stage == 1, x_c, s.x0))
        x = jnp.where(s.stage == 2, s.tally.best.x, x)
        return x, (s.stage < 2) & self.enabled

    def _secant_mode(self):
        # secant mode only with a usable slope on entry; an unknown one: eq. 15 throughout
        return jnp.asarray(False) if self.slope is None else self._usable(self.slope)

    def absorb(self, s: _Solve, x, f, aux, cost) -> _Solve:
        """The state after the evaluation ``(f, aux, cost)`` of the proposal ``x`` (no change
        once done). A disabled solve absorbs its masked first evaluation as converged."""
        hit = jnp.abs(f) < self.tol
        tally = _Tally(
            converged=s.tally.converged | hit,
            best=_keep_best(s.tally.best, x, f, aux),
            n_evals=s.tally.n_evals + 1,
            cost=jax.tree_util.tree_map(jnp.add, s.tally.cost, cost),
            last=(x, f),
            previous=s.tally.last,
        )
        first = self._start(s, x, f, aux, cost, hit)
        bracketing = self._bracketing(s, x, f, hit, tally)
        falsi = self._falsi(s, x, f, hit, tally)
        new = _select(s.stage == 0, bracketing, falsi)
        new = _select(s.stage == -1, first, new)
        return _select(s.stage < 2, new, s)

    def _start(self, s: _Solve, x0, f0, aux0, cost0, hit) -> _Solve:
        """After the warm start: the bracketing set up (eqs. 14-15), or done."""
        enabled = self.enabled
        converged = hit | ~enabled
        up = (1.0 if self.decreasing else -1.0) * f0 >= 0.0
        stop = jnp.where(up, x0 >= self.upper, x0 <= self.lower)
        x_next = x0
        if self.slope is not None:
            x_next = self._secant_from(x0, f0, self.slope, jnp.where(up, 1.0, -1.0))
        tally = _Tally(
            converged=converged,
            best=_Best(x0, f0, aux0),
            n_evals=enabled.astype(int),
            cost=jax.tree_util.tree_map(jnp.add, s.tally.cost, cost0),
            last=(x0, f0),
            previous=(x0, f0),
        )
        return s._replace(
            stage=jnp.where(converged | stop, 2, 0),
            f0=f0,
            up=up,
            f_same=f0,
            f_other=f0,
            x_next=x_next,
            stop=stop,
            tally=tally,
        )

    def _bracketing(self, s: _Solve, x_n, f_n, hit, tally) -> _Solve:
        """After a bracketing candidate: x_n = clip(x0 +/- n step), n = 1..n_bracket (eq. 15),
        or in secant mode the secant point from the last candidate on f's side: x - f(x) / s,
        with s the given slope for the first and the secant through the last two such
        candidates after it (a step of eq. 15 from the last candidate when that secant is not
        usable), until f changes sign. Then the bracket [last candidate with the sign of
        f(x0), first with the other sign], x_a < x_b, and the regula falsi on it, or done."""
        crossed = ~hit & (jnp.sign(f_n) != jnp.sign(s.f0))
        same = ~hit & ~crossed
        x_same, f_same = jnp.where(same, x_n, s.x_same), jnp.where(same, f_n, s.f_same)
        x_before = jnp.where(same, s.x_same, s.x_before)
        f_before = jnp.where(same, s.f_same, s.f_before)
        x_next = s.x_next
        if self.slope is not None:
            two = x_same != x_before
            s_now = (f_same - f_before) / jnp.where(two, x_same - x_before, 1.0)
            direction = jnp.where(s.up, 1.0, -1.0)
            x_next = self._secant_from(x_same, f_same, jnp.where(two, s_now, jnp.nan), direction)
        x_other = jnp.where(crossed, x_n, s.x_other)
        f_other = jnp.where(crossed, f_n, s.f_other)
        found = s.found | crossed
        bound = jnp.where(s.up, self.upper, self.lower)
        stop = s.stop | (same & (x_n == bound))
        count = s.count + 1
        end = found | stop | tally.converged | (count == self.n_bracket)
        swap = x_other < x_same
        # the candidate that crossed is the last evaluated: side a (+1) if it is the lower end
        last_kept = jnp.where(swap, 1, -1) if self.anderson_bjorck else jnp.zeros((), int)
        return s._replace(
            stage=jnp.where(end, jnp.where(found & ~tally.converged, 1, 2), 0),
            count=jnp.where(end, 0, count),
            x_same=x_same,
            f_same=f_same,
            x_before=x_before,
            f_before=f_before,
            x_other=x_other,
            f_other=f_other,
            x_next=x_next,
            found=found,
            stop=stop,
            x_a=jnp.where(swap, x_other, x_same),
            f_a=jnp.where(swap, f_other, f_same),
            x_b=jnp.where(swap, x_same, x_other),
            f_b=jnp.where(swap, f_same, f_other),
            last_kept=last_kept,
            tally=tally,
        )

    def _falsi(self, s: _Solve, x_c, f_c, hit, tally) -> _Solve:
        """After a regula-falsi iteration (eqs. 12-13): the endpoint whose f has the sign of
        f(x_c) replaced, with the Illinois rule if ``illinois`` (the Anderson-Bjorck factor
        instead of 1/2 if ``anderson_bjorck``)."""
        replace_a = ~hit & (jnp.sign(f_c) == jnp.sign(s.f_a))
        replace_b = ~hit & ~replace_a
        kept = jnp.where(replace_a, 1, jnp.where(replace_b, -1, 0))
        halve = self.illinois & (kept != 0) & (kept == s.last_kept)
        if self.anderson_bjorck:
            # m = 1 - f(c) / f(replaced end), or 1/2 when that is not in (0, 1)
            f_old = jnp.where(replace_a, s.f_a, s.f_b)
            m = 1.0 - f_c / jnp.where(f_old != 0.0, f_old, 1.0)
            factor = jnp.where((m > 0.0) & (m < 1.0), m, 0.5)
        else:
            factor = 0.5
        count = s.count + 1
        return s._replace(
            stage=jnp.where(tally.converged | (count == self.n_iter), 2, 1),
            count=count,
            x_a=jnp.where(replace_a, x_c, s.x_a),
            f_a=jnp.where(replace_a, f_c, jnp.where(halve & replace_b, factor * s.f_a, s.f_a)),
            x_b=jnp.where(replace_b, x_c, s.x_b),
            f_b=jnp.where(replace_b, f_c, jnp.where(halve & replace_a, factor * s.f_b, s.f_b)),
            last_kept=kept,
            tally=tally,
        )

    def result(self, s: _Solve) -> RegulaFalsiResult:
        """The result of a finished solve (or of where it stands)."""
        tally = s.tally
        (x_1, f_1), (x_2, f_2) = tally.last, tally.previous
        two = x_1 != x_2
        new_slope = jnp.where(two, (f_1 - f_2) / jnp.where(two, x_1 - x_2, 1.0), jnp.nan)
        if self.slope is not None:
            new_slope = jnp.where(two, new_slope, self.slope)
        status = jnp.where(
            tally.converged,
            RootStatus.ok,
            jnp.where(s.found, RootStatus.no_convergence, RootStatus.not_bracketed),
        )
        return RegulaFalsiResult(
            x=tally.best.x,
            f_x=tally.best.f,
            converged=tally.converged,
            n_evals_early_exit=tally.n_evals,
            n_evals_total=jnp.asarray(self.n_evals_total),
            status=status,
            aux=tally.best.aux,
            cost=tally.cost,
            slope=new_slope,
        )


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
