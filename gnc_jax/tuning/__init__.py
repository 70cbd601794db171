"""Gradient-based tuning of guidance gains: ``gj.tune``, ``gnc-jax tune``.

The gains to tune are chosen by their scenario names (``guidance.los.k1``, ``guidance.apn.n0``,
``guidance.skip_entry.k_range``, ...: :meth:`~gnc_jax.systems.AbstractSystem.tunable_names`).
An objective over a batch of dispersed runs is minimised with optax (Adam on a cosine-decayed
step, gradient clipping) through the laws' smooth relaxations, at the scenario's own relaxation
temperature T (``temperature=(start, end)`` anneals geometrically); every eighth of the steps
the hard logic is checked on training runs, and the result is the checked point (or the start)
where the hard objective is lowest. The result is evaluated with the hard logic (the normal
simulate path) on held-out runs, paired: initial and tuned gains fly the same held-out runs,
and the table gives a bootstrap confidence interval of the paired difference.

**Why no annealing by default.** A relaxation is only useful where it orders gains as the
hard logic does. Measured on 256 deep-impact-los runs, miss RMS + 10 s x Δv mean, hard logic
against the relaxed switch at T = 0.2 / 0.05 / 0.0125 / 0.003: (4, 1) 138.1 against 226.0 /
125.4 / 134.5 / 137.1; (3, 1) 125.7 against 232.0 / 118.8 / 123.6 / 125.0; (5.54, 0.88) 158.8
against 221.3 / 143.6 / 156.3 / 158.2. At 4 T the relaxed switch ranks (5.54, 0.88) best and
(3, 1) worst, the reverse of the hard logic: annealing from 4 T to T ended at gains 15 % worse
on held-out runs. Annealing from T to T / 4 went towards (3.4, 1.15) while T was high and
drifted back to (4.06, 1.48) as it fell (the pathwise gradient of a colder switch is rougher);
at the constant T = 0.05 the same tuning reached (1.85, 1.05), 16 % better on held-out runs.

The parts, one file each: ``objectives`` (the terms and their sums), ``parametrisation``
(the gains and their constraints), ``problem`` (the built problem and its run indices),
``optimisers`` (Adam and the evolution strategy), ``evaluation`` (hard logic, held-out runs),
``cost`` (the estimate checked against ``max_hours``), ``result`` (:class:`TuneResult`) and
``tuner`` (:func:`tune`).
"""

from .evaluation import (
    evaluate_heldout,
    hard_objectives,
    hard_scores,
    heldout_table,
    paired_interval,
    ranking_key,
)
from .objectives import TERMS, Objective, ObjectiveTerm, parse_objective
from .optimisers import default_optimizer, progress_line
from .parametrisation import Gain, Reparametrisation, resolve_gains, with_schedule_starts
from .problem import HELDOUT_MAX_RUNS, HELDOUT_OFFSET, TuningProblem, heldout_indices, train_indices
from .result import TuneResult, plot_training
from .tuner import tune

__all__ = [
    "tune",
    "TuneResult",
    "Objective",
    "ObjectiveTerm",
    "TERMS",
    "HELDOUT_MAX_RUNS",
    "HELDOUT_OFFSET",
    "Gain",
    "Reparametrisation",
    "TuningProblem",
    "parse_objective",
    "resolve_gains",
    "with_schedule_starts",
    "train_indices",
    "heldout_indices",
    "evaluate_heldout",
    "hard_objectives",
    "hard_scores",
    "ranking_key",
    "heldout_table",
    "paired_interval",
    "default_optimizer",
    "plot_training",
    "progress_line",
]
