import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from gnc_jax.root_finding import RootStatus, bounded_regula_falsi, regula_falsi


def _sequential_reference(
    f, x_prev, step, lower, upper, tol, n_bracket, n_iter, illinois, decreasing
):
    """Seed 003 eqs. 11-15 as a plain early-exit Python loop: (x, evaluations, status)."""
    x0 = min(max(x_prev, lower), upper)
    f0 = f(x0)
    evaluated = [(x0, f0)]

    def best():
        return min(reversed(evaluated), key=lambda p: abs(p[1]))[0]  # ties: the later

    if abs(f0) < tol:
        return x0, 1, RootStatus.ok
    up = (f0 if decreasing else -f0) >= 0
    bound = upper if up else lower
    x_same, f_same, bracket = x0, f0, None
    if x0 != bound:
        for n in range(1, n_bracket + 1):
            x_n = min(x0 + n * step, upper) if up else max(x0 - n * step, lower)
            f_n = f(x_n)
            evaluated.append((x_n, f_n))
            if abs(f_n) < tol:
                return x_n, len(evaluated), RootStatus.ok
            if np.sign(f_n) != np.sign(f0):
                bracket = sorted([(x_same, f_same), (x_n, f_n)])
                break
            x_same, f_same = x_n, f_n
            if x_n == bound:
                break
    if bracket is None:
        return best(), len(evaluated), RootStatus.not_bracketed
    (a, fa), (b, fb) = bracket
    last_kept = 0
    for _ in range(n_iter):
        c = min(max((a * fb - b * fa) / (fb - fa), a), b)
        fc = f(c)
        evaluated.append((c, fc))
        if abs(fc) < tol:
            return c, len(evaluated), RootStatus.ok
        if np.sign(fc) == np.sign(fa):
            a, fa, kept = c, fc, +1
            if illinois and last_kept == kept:
                fb *= 0.5
        else:
            b, fb, kept = c, fc, -1
            if illinois and last_kept == kept:
                fa *= 0.5
        last_kept = kept
    return best(), len(evaluated), RootStatus.no_convergence


# (name, jax function, numpy function, decreasing, lower, upper, x_prev, step)
CASES = [
    ("cubic", lambda x: x**3 - 2 * x - 5, lambda x: x**3 - 2 * x - 5, False, 0.0, 4.0, 0.3, 0.4),
    (
        "tanh",
        lambda x: 0.3 - jnp.tanh(4 * (x - 1.1)),
        lambda x: 0.3 - math.tanh(4 * (x - 1.1)),
        True,
        -2.0,
        3.0,
        2.9,
        0.25,
    ),
    (
        "range_vs_bank",
        lambda x: jnp.cos(x) - 0.35,
        lambda x: math.cos(x) - 0.35,
        True,
        0.0,
        math.pi,
        0.05,
        0.1,
    ),
    (
        "convex_exp",
        lambda x: jnp.exp(x) - 10.0,
        lambda x: math.exp(x) - 10.0,
        False,
        -1.0,
        5.0,
        4.9,
        0.3,
    ),
]


@pytest.mark.parametrize("illinois", [True, False])
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_matches_brentq_and_sequential_loop(case, illinois):
    _, f_jax, f_np, decreasing, lower, upper, x_prev, step = case
    tol, n_bracket, n_iter = 1e-11, 40, 60
    solve = jax.jit(
        lambda x: bounded_regula_falsi(
            f_jax,
            x,
            step,
            lower,
            upper,
            tol,
            n_bracket,
            n_iter,
            illinois=illinois,
            decreasing=decreasing,
        )
    )
    result = solve(x_prev)
    root = brentq(f_np, lower, upper, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    assert int(result.status) == RootStatus.ok and bool(result.converged)
    assert abs(float(result.f_x)) < tol
    assert float(result.x) == pytest.approx(root, abs=1e-9)
    # The start is far from the root: several bracketing steps are needed.
    assert abs(x_prev - root) > 2 * step
    x_ref, n_ref, status_ref = _sequential_reference(
        f_np, x_prev, step, lower, upper, tol, n_bracket, n_iter, illinois, decreasing
    )
    assert int(result.n_evals_early_exit) == n_ref
    assert int(result.status) == status_ref
    assert float(result.x) == pytest.approx(x_ref, abs=1e-12)
    assert int(result.n_evals_total) == 1 + n_bracket + n_iter


def test_illinois_beats_plain_regula_falsi_on_convex_function():
    # A wide bracket [-1, 4] on a convex f: plain regula falsi keeps x = 4 as an endpoint for
    # ever and creeps up from below; the Illinois rule releases it.
    f = lambda x: jnp.exp(x) - 10.0
    common = dict(
        step=5.0, lower=-1.0, upper=5.0, tol=1e-10, n_bracket=5, n_iter=200, decreasing=False
    )
    plain = bounded_regula_falsi(f, -1.0, illinois=False, **common)
    fast = bounded_regula_falsi(f, -1.0, illinois=True, **common)
    assert int(plain.status) == int(fast.status) == RootStatus.ok
    assert int(fast.n_evals_early_exit) <= 15 < 40 <= int(plain.n_evals_early_exit)


def test_warm_start_inside_tolerance_costs_one_evaluation():
    root = math.acos(0.35)
    result = bounded_regula_falsi(
        lambda x: jnp.cos(x) - 0.35, root + 1e-9, 0.1, 0.0, math.pi, 1e-6, 10, 10
    )
    assert int(result.n_evals_early_exit) == 1
    assert int(result.status) == RootStatus.ok
    assert float(result.x) == root + 1e-9


@pytest.mark.parametrize("c, bound", [(-1.5, math.pi), (1.5, 0.0)])
def test_not_bracketed_returns_the_bound(c, bound):
    # cos x - c has no root in [0, pi]: the search runs to the bound in the direction of eq. 15
    # and saturates there (the bound has the smaller |f| of the points tried).
    x_prev, step = 1.0, 0.3
    result = bounded_regula_falsi(
        lambda x: jnp.cos(x) - c, x_prev, step, 0.0, math.pi, 1e-8, 20, 10
    )
    assert int(result.status) == RootStatus.not_bracketed and not bool(result.converged)
    assert float(result.x) == bound
    assert float(result.f_x) == pytest.approx(math.cos(bound) - c)
    n_steps_to_bound = math.ceil(abs(bound - x_prev) / step)
    assert int(result.n_evals_early_exit) == 1 + n_steps_to_bound


def test_too_few_bracketing_steps_is_not_bracketed():
    result = bounded_regula_falsi(lambda x: jnp.cos(x) - 0.35, 0.05, 0.1, 0.0, math.pi, 1e-8, 3, 10)
    assert int(result.status) == RootStatus.not_bracketed
    assert int(result.n_evals_early_exit) == 4
    assert float(result.x) == pytest.approx(0.35)  # the last, best point tried


def test_a_plateau_not_bracketed_moves_to_the_last_point_tried():
    # a skip-out predicted for every bank tried (the same overshoot): the command moves
    # n_bracket steps towards the bound rather than staying at the warm start
    result = bounded_regula_falsi(lambda x: jnp.ones(()), 2.0, 0.1, 0.0, math.pi, 1e-3, 6, 6)
    assert int(result.status) == RootStatus.not_bracketed
    assert float(result.x) == pytest.approx(2.6)


def test_too_few_iterations_is_no_convergence():
    f = lambda x: jnp.exp(x) - 10.0
    result = bounded_regula_falsi(
        f, 4.9, 0.3, -1.0, 5.0, 1e-12, 30, 2, illinois=False, decreasing=False
    )
    assert int(result.status) == RootStatus.no_convergence and not bool(result.converged)
    n_bracketing = math.ceil((4.9 - math.log(10.0)) / 0.3)  # steps of 0.3 down to the root
    assert int(result.n_evals_early_exit) == 1 + n_bracketing + 2
    assert int(result.n_evals_total) == 1 + 30 + 2


def test_vmap_over_targets_equals_python_loop():
    def solve(c, x_prev):
        return bounded_regula_falsi(
            lambda x: jnp.cos(x) - c, x_prev, 0.2, 0.0, math.pi, 1e-9, 20, 30
        )

    cs = jnp.linspace(-1.2, 1.2, 49)  # includes targets with no root in [0, pi]
    x_prevs = jnp.linspace(0.0, math.pi, 49)[::-1]
    batched = jax.jit(jax.vmap(solve))(cs, x_prevs)
    one = jax.jit(solve)
    for i, (c, x_prev) in enumerate(zip(cs, x_prevs)):
        single = one(c, x_prev)
        for name in single._fields:
            if getattr(single, name) is None:  # aux, unused here
                continue
            np.testing.assert_array_equal(getattr(batched, name)[i], getattr(single, name))
    ok = batched.status == RootStatus.ok
    assert bool(jnp.all(ok == (jnp.abs(cs) <= 1.0)))
    assert bool(jnp.all(jnp.abs(jnp.cos(batched.x[ok]) - cs[ok]) < 1e-9))
    inner = jnp.abs(cs) < 0.99  # away from the ends, where acos is steep
    np.testing.assert_allclose(batched.x[inner], jnp.arccos(cs[inner]), atol=1e-8)


def test_gradient_through_the_corrector_is_finite():
    def root_of(c):
        return bounded_regula_falsi(
            lambda x: jnp.cos(x) - c, 0.1, 0.2, 0.0, math.pi, 1e-10, 20, 30
        ).x

    cs = jnp.array([-0.9, -0.3, 0.0, 0.35, 0.8, 1.5])  # 1.5: not bracketed, saturated
    grads = jax.vmap(jax.grad(root_of))(cs)
    assert bool(jnp.all(jnp.isfinite(grads)))
    # Where a root exists the secant-based derivative approximates dx/dc = -1/sin(x).
    expected = -1.0 / jnp.sqrt(1.0 - cs[:-1] ** 2)
    np.testing.assert_allclose(grads[:-1], expected, rtol=1e-4)


def _sequential_secant_reference(
    f, x_prev, slope, step, lower, upper, tol, n_bracket, n_iter, decreasing
):
    """The secant start and Anderson-Bjorck regula falsi as a plain early-exit Python loop:
    (x, evaluations, status, slope through the last two evaluations)."""
    monotone = 1.0 if decreasing else -1.0
    reach = n_bracket * step

    def usable(s):
        return math.isfinite(s) and monotone * s < 0.0

    x0 = min(max(x_prev, lower), upper)
    evaluated = [(x0, f(x0))]
    f0 = evaluated[0][1]

    def result(status):
        best = min(evaluated, key=lambda p: abs(p[1]))[0]
        (x1, f1), (x2, f2) = evaluated[-1], evaluated[-2 if len(evaluated) > 1 else -1]
        new_slope = (f1 - f2) / (x1 - x2) if x1 != x2 else slope
        return best, len(evaluated), status, new_slope

    if abs(f0) < tol:
        return result(RootStatus.ok)
    up = monotone * f0 >= 0
    direction, bound = (1.0, upper) if up else (-1.0, lower)
    secant = usable(slope)

    def secant_from(x, fx, s):
        if not usable(s):
            return x + direction * step
        return x + min(max(-fx / s, -reach), reach)

    same, before, bracket = (x0, f0), None, None
    x_next = secant_from(x0, f0, slope) if secant else None
    if x0 != bound:
        for n in range(1, n_bracket + 1):
            x_n = x_next if secant else x0 + direction * n * step
            x_n = min(x_n, upper) if up else max(x_n, lower)
            f_n = f(x_n)
            evaluated.append((x_n, f_n))
            if abs(f_n) < tol:
                return result(RootStatus.ok)
            if np.sign(f_n) != np.sign(f0):
                bracket = sorted([same, (x_n, f_n)])
                last_kept = 1 if x_n < same[0] else -1
                break
            before, same = same, (x_n, f_n)
            if x_n == bound:
                break
            if secant:
                s = (
                    (same[1] - before[1]) / (same[0] - before[0])
                    if same[0] != before[0]
                    else math.nan
                )
                x_next = secant_from(same[0], same[1], s)
    if bracket is None:
        return result(RootStatus.not_bracketed)
    (a, fa), (b, fb) = bracket
    for _ in range(n_iter):
        c = min(max((a * fb - b * fa) / (fb - fa), a), b)
        fc = f(c)
        evaluated.append((c, fc))
        if abs(fc) < tol:
            return result(RootStatus.ok)
        replace_a = np.sign(fc) == np.sign(fa)
        kept = 1 if replace_a else -1
        m = 1.0 - fc / (fa if replace_a else fb)
        m = m if 0.0 < m < 1.0 else 0.5
        if replace_a:
            if last_kept == kept:
                fb *= m
            a, fa = c, fc
        else:
            if last_kept == kept:
                fa *= m
            b, fb = c, fc
        last_kept = kept
    return result(RootStatus.no_convergence)


SLOPE_FACTORS = [1.0, 0.6, 1.7, -1.0, math.nan]  # exact, too flat, too steep, wrong sign, unknown


@pytest.mark.parametrize("factor", SLOPE_FACTORS)
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_secant_start_matches_brentq_and_sequential_loop(case, factor):
    """The secant mode (a slope from the previous solve) with Anderson-Bjorck regula falsi
    against scipy's brentq root and an independent early-exit Python loop, for slopes that
    are exact at the start, off by a factor, of the wrong sign (eq. 15 steps) or unknown."""
    _, f_jax, f_np, decreasing, lower, upper, x_prev, step = case
    tol, n_bracket, n_iter = 1e-11, 40, 60
    h = 1e-7
    slope = factor * (f_np(x_prev + h) - f_np(x_prev - h)) / (2 * h)
    result = jax.jit(
        lambda x, s: bounded_regula_falsi(
            f_jax,
            x,
            step,
            lower,
            upper,
            tol,
            n_bracket,
            n_iter,
            decreasing=decreasing,
            slope=s,
            anderson_bjorck=True,
        )
    )(x_prev, slope)
    root = brentq(f_np, lower, upper, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    assert int(result.status) == RootStatus.ok
    assert float(result.x) == pytest.approx(root, abs=1e-9)
    x_ref, n_ref, status_ref, slope_ref = _sequential_secant_reference(
        f_np, x_prev, slope, step, lower, upper, tol, n_bracket, n_iter, decreasing
    )
    assert int(result.n_evals_early_exit) == n_ref
    assert int(result.status) == status_ref
    assert float(result.x) == pytest.approx(x_ref, abs=1e-12)
    # (two last points within 1e-10 of each other: the secant keeps about 5 digits)
    assert float(result.slope) == pytest.approx(slope_ref, rel=1e-3)
    # the slope of the last two evaluations is that of f near the root
    h = 1e-6
    assert float(result.slope) == pytest.approx(
        (f_np(root + h) - f_np(root - h)) / (2 * h), rel=0.05
    )


def test_secant_start_needs_fewer_evaluations_near_a_moving_root():
    """What the corrector sees from one cycle to the next: the root moved a little, the slope
    of the last cycle is close. The secant start then needs two evaluations where the seed's
    eq. 15 bracketing needs about four; an unknown slope reproduces eq. 15 exactly."""
    f = lambda x: 1.0e3 * (jnp.exp(-2.0 * x) - 0.3)  # noqa: E731  (decreasing, convex)
    root = -0.5 * math.log(0.3)
    x_prev, slope = root - 0.02, -2.0e3 * 0.3 * 1.05  # last cycle's root and slope
    common = dict(step=0.0873, lower=0.0, upper=math.pi, tol=5.0, n_bracket=6, n_iter=6)
    seed = bounded_regula_falsi(f, x_prev, **common)
    secant = bounded_regula_falsi(f, x_prev, slope=slope, anderson_bjorck=True, **common)
    unknown = bounded_regula_falsi(f, x_prev, slope=jnp.nan, **common)
    assert int(seed.status) == int(secant.status) == RootStatus.ok
    assert int(secant.n_evals_early_exit) == 2 < int(seed.n_evals_early_exit)
    for name in ("x", "f_x", "n_evals_early_exit", "status"):
        np.testing.assert_array_equal(getattr(unknown, name), getattr(seed, name))


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_anderson_bjorck_needs_no_more_evaluations_than_illinois(case):
    """Both are regula falsi on the same bracket and find brentq's root; the Anderson-Bjorck
    factor never costs evaluations against the Illinois 1/2 on these functions."""
    _, f_jax, f_np, decreasing, lower, upper, x_prev, step = case
    common = dict(tol=1e-10, n_bracket=40, n_iter=200, decreasing=decreasing)
    illinois = bounded_regula_falsi(f_jax, x_prev, step, lower, upper, **common)
    ab = bounded_regula_falsi(f_jax, x_prev, step, lower, upper, anderson_bjorck=True, **common)
    root = brentq(f_np, lower, upper, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    assert int(ab.status) == int(illinois.status) == RootStatus.ok
    assert float(ab.x) == pytest.approx(root, abs=1e-9)
    assert int(ab.n_evals_early_exit) <= int(illinois.n_evals_early_exit)


def test_anderson_bjorck_beats_illinois_on_a_skip_like_range_error():
    # decreasing and convex, like the predicted range against the bank
    f = lambda x: 5e3 * jnp.exp(-3.0 * x) - 1e3 * x - 500.0  # noqa: E731
    common = dict(tol=1e-4, n_bracket=20, n_iter=200)
    illinois = bounded_regula_falsi(f, 0.0, 0.5, 0.0, 3.0, **common)
    ab = bounded_regula_falsi(f, 0.0, 0.5, 0.0, 3.0, anderson_bjorck=True, **common)
    assert int(ab.status) == int(illinois.status) == RootStatus.ok
    assert abs(float(ab.x) - float(illinois.x)) < 1e-6
    assert int(ab.n_evals_early_exit) < int(illinois.n_evals_early_exit)


@pytest.mark.parametrize("secant", [False, True])
def test_machine_driven_per_run_equals_the_vmapped_slots(secant):
    """The :class:`RegulaFalsi` machine driven run by run (a Python loop that evaluates each
    run's proposals until it is done, as a caller that advances every run on its own does)
    gives the same solve as the vmapped fixed slots of :func:`bounded_regula_falsi`, on random
    brackets, starts and (for the secant start) slopes: same root, evaluations, status and
    slope; and the evaluations agree with the plain sequential reference."""
    rng = np.random.default_rng(3)
    n = 40
    roots = rng.uniform(0.3, 2.8, n)
    curvature = rng.uniform(0.0, 0.4, n)
    x_prevs = np.clip(roots + rng.uniform(-1.0, 1.0, n), 0.0, math.pi)
    slopes = -rng.uniform(0.5, 2.0, n) if secant else np.full(n, np.nan)
    common = dict(step=0.15, lower=0.0, upper=math.pi, tol=1e-6, n_bracket=8, n_iter=8)

    def f(x, root, k):  # decreasing, convex or not, the root inside [0, pi]
        return -(x - root) - k * (x - root) ** 3

    def slots(root, k, x_prev, slope):
        return bounded_regula_falsi(
            lambda x: f(x, root, k),
            x_prev,
            slope=slope if secant else None,
            anderson_bjorck=secant,
            **common,
        )

    batched = jax.jit(jax.vmap(slots))(roots, curvature, x_prevs, slopes)
    for i in range(n):
        solver = regula_falsi(**common, slope=slopes[i] if secant else None, anderson_bjorck=secant)
        s = solver.init(x_prevs[i], None, jnp.zeros(()))
        while not bool(solver.done(s)):
            x, active = solver.propose(s)
            assert bool(active)
            s = solver.absorb(s, x, f(x, roots[i], curvature[i]), None, jnp.zeros(()))
        one = solver.result(s)
        for name in ("n_evals_early_exit", "status"):
            np.testing.assert_array_equal(getattr(one, name), getattr(batched, name)[i])
        for name in ("x", "f_x", "slope"):  # eager against compiled: the last bit may differ
            np.testing.assert_allclose(
                getattr(one, name), getattr(batched, name)[i], rtol=1e-12, atol=1e-12
            )
        if not secant:
            f_np = lambda x, i=i: float(f(x, roots[i], curvature[i]))  # noqa: E731
            x_ref, n_ref, status_ref = _sequential_reference(
                f_np, x_prevs[i], **common, illinois=True, decreasing=True
            )
            assert int(one.n_evals_early_exit) == n_ref and int(one.status) == status_ref
            assert float(one.x) == pytest.approx(x_ref, abs=1e-12)
