"""Tuning objectives: the built-in terms (:data:`TERMS`), their weighted sums and user
callables, hard and smooth (:class:`Objective`, :func:`parse_objective`)."""

import dataclasses
import inspect
import math
import re
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp

from .._status import Status
from ..scenario import Scenario, ScenarioError
from ..systems.base import AbstractSystem


def counted(outcomes):
    """Per run, whether it counts: status ``ok`` and every float outcome finite (as a study
    does, a run with a non-finite float outcome is a failed ``nan`` run)."""
    ok = outcomes.status == Status.ok
    for x in outcomes:
        if jnp.issubdtype(x.dtype, jnp.floating):
            ok &= jnp.isfinite(x).reshape(x.shape[0], -1).all(axis=1)
    return ok


def _wmean(x, w):
    """The mean of ``x`` over the runs that count (weight > 0); NaN when none does, so that
    gains that fail every run rank last, never at the best possible value 0."""
    total = jnp.sum(w)
    mean = jnp.sum(jnp.where(w > 0, x, 0.0) * w) / jnp.maximum(total, 1.0)
    return jnp.where(total > 0, mean, jnp.nan)


def _miss_rms(out, w, arg, t):
    return jnp.sqrt(_wmean(out.miss_m**2, w))


def _dv_mean(out, w, arg, t):
    return _wmean(out.dv_mps, w)


def _chute_rms(out, w, arg, t):
    return jnp.sqrt(_wmean(out.downrange_err_km**2 + out.crossrange_err_km**2, w))


def _impact_distance(out):
    # the B-plane point relative to the target's centre where the outcome has it (impactor:
    # the miss is from the aim point), else the miss itself (intercept: aimed at the centre)
    if hasattr(out, "b_t_m"):
        return jnp.sqrt(out.b_t_m**2 + out.b_r_m**2)
    return out.miss_m


def _hit_probability(out, w, radius, t):
    """1 - P(hit). Without ``radius``: the study's hit rule (:mod:`gnc_jax.geometry.silhouette`,
    a hit is ``silhouette_ratio < 1``: the B-plane point inside the target's capture
    silhouette); smooth: a logistic of width ``t`` in that ratio. With ``radius`` (m): a hit is
    an impact point within ``radius`` of the target's centre; smooth: a logistic of width
    ``t x radius``."""
    if radius is None:
        if t is None:
            return 1.0 - _wmean((out.silhouette_ratio < 1.0).astype(float), w)
        return 1.0 - _wmean(jax.nn.sigmoid((1.0 - out.silhouette_ratio) / t), w)
    d = _impact_distance(out)
    if t is None:
        return 1.0 - _wmean((d <= radius).astype(float), w)
    return 1.0 - _wmean(jax.nn.sigmoid((radius - d) / (t * radius)), w)


def _peak_load(out, w, limit, t):
    """Mean excess of the peak load over ``limit`` (g); smooth: a softplus of width t x limit."""
    excess = out.load_peak_g - limit
    if t is None:
        return _wmean(jnp.maximum(excess, 0.0), w)
    width = t * limit
    return _wmean(width * jax.nn.softplus(excess / width), w)


def _failed(out, runs, arg, t):
    """The fraction of the runs (``runs`` 1, padding 0) that did not count (:func:`counted`),
    hard and smooth alike: a count has no relaxation, and no gradient."""
    failed = jnp.sum(jnp.where(counted(out), 0.0, runs))
    return failed / jnp.maximum(jnp.sum(runs), 1.0)


@dataclasses.dataclass(frozen=True)
class ObjectiveTerm:
    """A built-in objective term: ``fn(outcomes, weights, arg, temperature)`` (temperature
    ``None``: the hard value), the outcome fields it reads, and what its argument means.
    ``weights`` is 1 for the runs that end ``ok`` and 0 for the others, or, for a term over
    every run (``over_ok=False``), 1 for every run and 0 for a batch's padding."""

    fn: Callable
    fields: tuple[str, ...]
    doc: str
    arg: str = ""  # meaning of the argument in name(arg); "" = none
    over_ok: bool = True
    arg_fields: tuple[str, ...] | None = None  # read instead of ``fields`` when an optional
    # argument is given; None: the argument, if any, is required

    def fields_for(self, arg) -> tuple[str, ...]:
        """The outcome fields the term reads with argument ``arg`` (None: not given)."""
        return self.fields if arg is None or self.arg_fields is None else self.arg_fields


TERMS: dict[str, ObjectiveTerm] = {
    "miss_rms": ObjectiveTerm(_miss_rms, ("miss_m",), "RMS of the miss, m"),
    "dv_mean": ObjectiveTerm(_dv_mean, ("dv_mps",), "mean Δv, m/s"),
    "hit_probability": ObjectiveTerm(
        _hit_probability,
        ("silhouette_ratio",),
        "1 - P(hit): the study's hit rule (inside the target's B-plane silhouette), or with an "
        "argument 1 - P(impact within that radius of the target's centre)",
        arg="RADIUS_M, optional: a radius in m about the target's centre instead of its shape",
        arg_fields=("miss_m",),
    ),
    "chute_rms": ObjectiveTerm(
        _chute_rms,
        ("downrange_err_km", "crossrange_err_km"),
        "RMS of the chute-deploy error, km",
    ),
    "peak_load": ObjectiveTerm(
        _peak_load, ("load_peak_g",), "mean excess of the peak load over a limit, g", "LIMIT_G in g"
    ),
    "failed": ObjectiveTerm(
        _failed, (), "fraction of the runs that did not end ok (over every run)", over_ok=False
    ),
}
"""Built-in objective terms by name: a weighted sum of them is written ``"miss_rms+10*dv_mean"``
(``peak_load(8)``, ``hit_probability(300)`` take an argument). Every term but ``failed`` is
taken over the runs that end ``ok``; ``failed`` counts the others, so that
``"miss_rms+100*failed"`` prices a failed run where the other terms cannot see it."""

_TERM_SEPARATOR = re.compile(r"(?<![0-9.][eE])\+")
"""A '+' between terms, not the sign of a weight's exponent (``1e+3*miss_rms``)."""
_TERM_RE = re.compile(r"^\s*(?:([0-9.eE+-]+)\s*\*\s*)?([a-z_]+)\s*(?:\(\s*([^)]*)\s*\))?\s*$")


def _term_forms(name: str, term: ObjectiveTerm) -> str:
    """How a term is written: ``name``, ``name(ARG)``, or both where the argument is optional."""
    if not term.arg:
        return name
    with_arg = f"{name}({term.arg.split(' ')[0].rstrip(',')})"
    return with_arg if term.arg_fields is None else f"{name}, {with_arg}"


def term_forms() -> str:
    """The built-in terms as written in an objective, ``failed`` apart (the CLI's help)."""
    return ", ".join(_term_forms(n, t) for n, t in TERMS.items() if n != "failed")


def _allowed_objectives() -> str:
    return (
        ", ".join(_term_forms(n, t) for n, t in TERMS.items())
        + ", weighted sums such as 'miss_rms+10*dv_mean', or a callable(outcomes, weights)"
    )


@dataclasses.dataclass(frozen=True)
class Objective:
    """A tuning objective: a weighted sum of built-in terms, or a user callable.

    ``value(outcomes, weights, temperature)`` is the smooth objective at ``temperature`` and the
    hard one for ``temperature=None``; ``weights`` is 1 for the runs that count (status ``ok``)
    and 0 for the others (a built-in term is NaN when no run counts), ``runs`` 1 for the runs
    of the batch and 0 for its padding (default: every run), which the ``failed`` term is
    over. A user callable ``fn(outcomes, weights)`` is used for both; one that takes a
    ``runs`` argument, ``fn(outcomes, weights, runs)``, also gets that mask (all ones where no
    padding), to tell a failed run (``weights`` 0, ``runs`` 1) from padding (both 0).
    """

    spec: str
    terms: tuple[tuple[float, str, float | None], ...] = ()  # (weight, name, argument)
    fn: Callable | None = None

    @property
    def structure(self):
        """What compiled code depends on: the terms and their arguments, not their weights
        (an argument of the compiled functions: a sweep over weights compiles once)."""
        return tuple((name, arg) for _, name, arg in self.terms), self.fn

    @property
    def weights(self):
        return jnp.asarray([w for w, _, _ in self.terms], dtype=jnp.float64)

    @property
    def takes_runs(self) -> bool:
        """Whether this is a user callable that takes the ``runs`` mask (and so can count the
        failed runs itself)."""
        return self.fn is not None and _takes_runs(self.fn)

    def value(self, outcomes, weights, temperature=None, term_weights=None, runs=None):
        if self.fn is not None:
            if not self.takes_runs:
                return self.fn(outcomes, weights)
            return self.fn(outcomes, weights, runs=jnp.ones_like(weights) if runs is None else runs)
        term_weights = self.weights if term_weights is None else term_weights
        return sum(
            term_weights[i] * _term(name, outcomes, weights, runs, arg, temperature)
            for i, (_, name, arg) in enumerate(self.terms)
        )

    def term_values(self, outcomes, weights, runs=None) -> dict[str, float]:
        """The hard value of each term (for the held-out table)."""
        return {
            _term_label(name, arg): float(_term(name, outcomes, weights, runs, arg, None))
            for _, name, arg in self.terms
        }

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(f for _, name, arg in self.terms for f in TERMS[name].fields_for(arg))


def _takes_runs(fn) -> bool:
    """Whether a user objective takes the ``runs`` mask (a parameter of that name or
    ``**kwargs``)."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):  # a builtin or extension callable: two arguments
        return False
    return any(p.name == "runs" or p.kind is p.VAR_KEYWORD for p in params)


def _term(name, outcomes, weights, runs, arg, temperature):
    """Term ``name`` over the ``ok`` runs (``weights``) or over every run (``runs``)."""
    term = TERMS[name]
    if not term.over_ok:
        weights = jnp.ones_like(weights) if runs is None else runs
    return term.fn(outcomes, weights, arg, temperature)


def _term_label(name, arg):
    return name if arg is None else f"{name}({arg:g})"


def parse_objective(objective, scenario: Scenario) -> Objective:
    """An :class:`Objective` from a spec string (``"miss_rms+10*dv_mean"``), a mapping
    ``{term: weight}``, a callable ``fn(outcomes, weights)``, or ``None`` (the system's
    ``smooth_objective``, hard and smooth alike). Raises :class:`ScenarioError` naming the bad
    term."""
    if callable(objective):
        return Objective(getattr(objective, "__name__", "callable"), fn=objective)
    if objective is None:
        system = scenario.system
        if type(system).smooth_objective is AbstractSystem.smooth_objective:
            raise ScenarioError(
                f"objective: none given and {system.name} has no smooth_objective; allowed: "
                f"{_allowed_objectives()}"
            )
        return Objective(
            f"{system.name}.smooth_objective", fn=lambda out, w: system.smooth_objective(out)
        )
    if isinstance(objective, dict):
        objective = "+".join(f"{w!r}*{n}" for n, w in objective.items())
    if not isinstance(objective, str) or not objective.strip():
        raise ScenarioError(f"objective: {objective!r}; allowed: {_allowed_objectives()}")
    terms = []
    for part in _TERM_SEPARATOR.split(objective):
        m = _TERM_RE.match(part)
        name = m.group(2) if m else part.strip()
        if m is None or name not in TERMS:
            raise ScenarioError(
                f"objective: {part.strip()!r} in {objective!r}; allowed: {_allowed_objectives()}"
            )
        try:
            weight = float(m.group(1)) if m.group(1) else 1.0
            arg = float(m.group(3)) if m.group(3) else None
        except ValueError:
            raise ScenarioError(
                f"objective: {part.strip()!r}: not a number; allowed: {_allowed_objectives()}"
            ) from None
        term = TERMS[name]
        if not 0 <= weight < math.inf:
            raise ScenarioError(
                f"objective: {part.strip()!r}: weight {weight:g}; allowed: a finite weight >= 0 "
                "(the tuner minimises the sum)"
            )
        if term.arg and term.arg_fields is None and arg is None:
            raise ScenarioError(f"objective: {name} needs an argument; allowed: {name}({term.arg})")
        if not term.arg and arg is not None:
            raise ScenarioError(f"objective: {name} takes no argument; allowed: {name}")
        if arg is not None and not 0 < arg < math.inf:
            raise ScenarioError(
                f"objective: {part.strip()!r}: argument {arg:g}; allowed: {name}(X), X finite "
                f"and > 0: the {term.arg}"
            )
        terms.append((weight, name, arg))
    if not any(w > 0 for w, _, _ in terms):
        raise ScenarioError(
            f"objective: {objective!r} weighs every term 0; allowed: at least one weight > 0"
        )
    return Objective(objective.replace(" ", ""), tuple(terms))


def _check_fields(objective: Objective, outcome_fields: Sequence[str], kind: str) -> None:
    for f in objective.fields:
        if f not in outcome_fields:
            name = next(n for _, n, a in objective.terms if f in TERMS[n].fields_for(a))
            usable = [n for n, t in TERMS.items() if all(x in outcome_fields for x in t.fields)]
            raise ScenarioError(
                f"objective: {name} needs the outcome {f!r}, which {_article(kind)} {kind} run "
                f"does not have; allowed for {kind}: {', '.join(usable)}"
            )


def _article(word: str) -> str:
    return "an" if word[:1].lower() in "aeiou" else "a"
