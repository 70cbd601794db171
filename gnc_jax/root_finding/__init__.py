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

The parts: ``result`` (the status and the result), ``state`` (what a solve carries),
``machine`` (:class:`RegulaFalsi`) and ``bounded`` (the ``lax.scan`` drivers).
"""

from .bounded import Objective, bounded_regula_falsi, bounded_regula_falsi_with_aux, regula_falsi
from .machine import RegulaFalsi
from .result import RegulaFalsiResult, RootStatus

__all__ = [
    "RootStatus",
    "RegulaFalsiResult",
    "RegulaFalsi",
    "Objective",
    "regula_falsi",
    "bounded_regula_falsi",
    "bounded_regula_falsi_with_aux",
]
