"""What a solve returns: its status (:class:`RootStatus`) and :class:`RegulaFalsiResult`."""

import enum
from typing import Any, NamedTuple

from .._types import Array, Bool, Int, Scalar


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
