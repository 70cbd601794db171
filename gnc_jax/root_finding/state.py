"""The state a solve carries between evaluations: the best point, the tally and the stage."""

from typing import Any, NamedTuple

from .._types import Array, Bool, Int, Scalar


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
