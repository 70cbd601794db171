"""Property-based fuzzing of every registered system.

A *case* is a system's ``example`` scenario with its ``test_overrides``, plus 1-4 fields of its
schema (the chosen law's ``[guidance.<law>]`` table for guidance sections) set to a value
inside the field's declared range (edges, log-uniform over wide ranges, typical values) or
just outside it (past an edge, wrong type, wrong length, NaN/inf, 1e200 / 1e-300 in unbounded
fields, wrong strings). The property: a case either

* is **refused** with one :class:`~gnc_jax.scenario.ScenarioError` line that names a field
  (when loading, when building, or by the cost estimate before compilation), or
* **runs** a small study to finite outcomes: ``ran`` when every run is ``ok``, ``flagged`` when
  some runs carry a non-``ok`` status (counted in ``failed``);

never a traceback, a hang or a non-finite statistic. :func:`run_case` classifies one case;
:func:`cases` is the hypothesis strategy that draws them. ``tests/test_fuzz.py`` runs a short
campaign in CI and ``tests/fuzz_campaign.py`` a long one, one worker process per case stream
with a per-case time limit.
"""

import dataclasses
import datetime
import math
import time
import traceback
from typing import Any

import numpy as np
from hypothesis import strategies as st

import gnc_jax as gj
from gnc_jax.schema import Field

RUNS = 4
"""Runs per fuzz study: enough to exercise the batch and the statistics, cheap to run. They run
in one chunk of four on every device: the example's program is then the one
tests/test_family.py compiles for its chunked study, read from the session's XLA cache."""
MAX_HOURS = 60.0 / 3600.0
"""A fuzz study estimated (by the system's cost model) to take longer than a minute is refused
before compilation: that is how a runaway case is told apart from a hang."""

OUTCOMES = ("ran", "flagged", "refused", "traceback", "hang", "nan_stats", "invariant")
"""What a case can come to. The first three are allowed; the others are failures:
``traceback`` any exception but ScenarioError, ``hang`` over the per-case time limit (only the
campaign's worker can tell), ``nan_stats`` a non-finite statistic in the summary,
``invariant`` a broken bookkeeping rule (a refusal of several lines or naming no field; an
``ok`` run with a non-finite outcome; ``failed`` not counting every non-``ok`` run)."""
FAILURES = ("traceback", "hang", "nan_stats", "invariant")

_CAPSULE = gj.get_system("capsule").schema()
SHAPE_FIELDS = {
    # Floats whose value decides a loop length, a static field or an array shape (every field
    # that is not a float or a fixed-length list of floats is taken to), measured by comparing
    # the compiled program's key (tree structure, shapes and static fields of the built
    # (params, law)) of the example with that of a one-field change, plus the step sizes and
    # the time-of-flight inputs. Drawing any other field reuses the executable compiled for the
    # example, so the CI campaign draws these only outside their range (refused before
    # anything is built).
    "toy-intercept": {"geometry.range_m", "geometry.closing_speed_mps", "guidance.dt_s"},
    "intercept": {
        "guidance.coast_s",
        "guidance.dt_s",
        "navigation.image_interval_s",
        *(
            f"approach.{b}_{q}"
            for b in ("target", "impactor")
            for q in ("position_km", "velocity_kmps")
        ),
    },
    "impactor": {
        "guidance.dt_s",
        "camera.image_interval_s",
        "guidance.retarget_tgo_s",
        "approach.position_km",
        "approach.velocity_kmps",
    },
    "capsule": {
        "simulation.dt_s",
        "simulation.control_dt_s",
        "simulation.max_time_s",
        "guidance.pc_period_s",
        # not shapes, but a new reference trajectory (a design of about a minute, cached)
        *(f"{s}.{n}" for s in ("entry", "vehicle", "atmosphere") for n in _CAPSULE[s]),
        "guidance.skip_entry.kepler_load_g",
        "reference.v_end_mps",
        "reference.w_margin",
    },
    # the aim point: a new nominal transfer (a design of a few seconds, cached)
    "midcourse": {"navigation.interval_days", "dynamics.window_days", "mission.aim_b_km"},
}


def shape_fields(system) -> set[str]:
    """The fields of ``system`` that change the compiled program: ``SHAPE_FIELDS`` and every
    field that is not a float or a list of floats of fixed length."""
    fields = {f"{s}.{n}": f for s, table in system.schema().items() for n, f in table.items()}
    return SHAPE_FIELDS.get(system.name, set()) | {
        n
        for n, f in fields.items()
        if f.kind != "float" and not (f.kind == "floats" and f.length is not None)
    }


def fields_of(system, law: str | None) -> dict[str, Field]:
    """``{"section.field": Field}`` of a system flying ``law``: every section except the
    ``[guidance.<other law>]`` tables."""
    out = {}
    for section, fields in system.schema().items():
        head, _, table = section.partition(".")
        if head == "guidance" and table and table != law:
            continue
        for name, field in fields.items():
            out[f"{section}.{name}"] = field
    return out


# ---- values inside the declared range ----


def _inside_number(field: Field, integer: bool) -> st.SearchStrategy:
    lo, hi, default = field.lo, field.hi, field.default
    options = [st.just(default)]
    if lo is not None:
        edge = math.nextafter(lo, math.inf) if field.lo_open else lo
        options.append(st.just(int(math.ceil(edge)) if integer else edge))
    if hi is not None:
        options.append(st.just(hi))
    a = lo if lo is not None else -max(abs(default), 1.0) * 1e3
    b = hi if hi is not None else max(abs(default), 1.0) * 1e3
    if integer:
        a, b = int(math.ceil(a + (1 if field.lo_open else 0))), int(b)
        options.append(st.integers(a, min(b, a + 16)))
        if b > 0 and b / max(a, 1) > 100:  # log-uniform over a wide range
            options.append(
                st.floats(math.log(max(a, 1)), math.log(b)).map(lambda x: int(math.exp(x)))
            )
        return st.one_of(options).filter(lambda v: a <= v <= b)
    options.append(st.floats(a, b, exclude_min=field.lo_open))
    if a >= 0.0 and b / max(a, 1e-12) > 1e3:  # log-uniform over a wide range
        low = math.log10(max(a, abs(default) * 1e-6, 1e-12))
        options.append(st.floats(low, math.log10(b)).map(lambda x: 10.0**x))
    if default:  # typical values: the default scaled by up to a decade each way
        options.append(st.floats(-1.0, 1.0).map(lambda x: default * 10.0**x))

    def allowed(v):
        too_low = lo is not None and (v <= lo if field.lo_open else v < lo)
        return math.isfinite(v) and not too_low and (hi is None or v <= hi)

    return st.one_of(options).filter(allowed)


def _epochs() -> st.SearchStrategy:
    days = st.integers(0, 200 * 365)
    return days.map(lambda d: (datetime.date(1900, 1, 1) + datetime.timedelta(d)).isoformat())


def _near_default_epoch(default: str) -> st.SearchStrategy:
    base = datetime.date.fromisoformat(default[:10])
    return st.integers(-60, 60).map(lambda d: (base + datetime.timedelta(d)).isoformat())


def inside(field: Field) -> st.SearchStrategy:
    """A value the declaration allows."""
    kind = field.kind
    if kind == "bool":
        return st.booleans()
    if kind == "str":
        if field.choices:
            return st.sampled_from(field.choices)
        if _is_date(field.default):
            return st.one_of(_near_default_epoch(field.default), _epochs())
        return st.just(field.default)
    if kind in ("float", "int"):
        return _inside_number(field, kind == "int")
    if kind == "floats":
        element = dataclasses.replace(field, kind="float", default=_typical(field.default))
        if field.lo is None and field.hi is None:
            # unbounded vectors (positions, directions): the default nudged per component, or
            # an edge the declaration allows: zero, an axis, reversed, scaled by 1e-300 / 1e200
            default = list(field.default)
            n = len(default)
            axes = [[float(i == j) for j in range(n)] for i in range(n)]
            edges = [[0.0] * n, *axes, [-v for v in default]]
            edges += [[v * scale for v in default] for scale in (1e-300, 1e200)]
            nudge = st.lists(st.floats(-0.5, 0.5), min_size=n, max_size=n).map(
                lambda ds: [v * (1.0 + d) + d for v, d in zip(default, ds)]
            )
            tiny = st.tuples(st.integers(0, n - 1), st.sampled_from([1e-300, -1e-300, 1e200]))
            return st.one_of(
                nudge,
                nudge,
                st.sampled_from(edges),
                tiny.map(lambda x: [x[1] if i == x[0] else v for i, v in enumerate(default)]),
            )
        if field.length is not None:
            return st.lists(inside(element), min_size=field.length, max_size=field.length)
        n = max(field.min_length, 1)
        return st.one_of(
            st.lists(inside(element), min_size=n, max_size=n + 4).map(sorted),
            st.lists(inside(element), min_size=n, max_size=n + 4),
        )
    raise AssertionError(kind)


def _typical(values) -> float:
    values = [abs(v) for v in values if v]
    return float(np.median(values)) if values else 1.0


def _is_date(text) -> bool:
    try:
        datetime.date.fromisoformat(str(text)[:10])
        return True
    except ValueError:
        return False


# ---- values just outside it ----

_WRONG_TYPES = st.sampled_from(["abc", "1.0", True, [1.0], {"x": 1.0}])
_NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])
_HUGE_TINY = st.sampled_from([1e200, -1e200, 1e-300, -1e-300])


def _outside_number(field: Field, integer: bool) -> st.SearchStrategy:
    lo, hi = field.lo, field.hi
    options = [_WRONG_TYPES, _NON_FINITE]
    bit = st.floats(1e-9, 1.0)
    if lo is not None:
        options.append(
            st.just(lo) if field.lo_open else bit.map(lambda b: lo - max(abs(lo), 1) * b)
        )
        options.append(st.just(lo - 1e9))
    if hi is not None:
        options.append(bit.map(lambda b: hi + max(abs(hi), 1) * b))
    if lo is None or hi is None:
        options.append(_HUGE_TINY)  # allowed by an open-ended range, beyond any physics
    if integer:
        options.append(st.sampled_from([2.5, 3.0]))  # not an integer
        if lo is not None:
            options.append(st.just(int(lo) - 1))
        if hi is not None:
            options.append(st.just(int(hi) + 1))
    elif lo is not None and hi is not None:
        options.append(_HUGE_TINY)
    return st.one_of(options)


def outside(field: Field) -> st.SearchStrategy:
    """A value just outside the declaration (refused), or allowed only by an open-ended range
    (1e200 where no upper bound is declared: it must run to flagged outcomes or be refused)."""
    kind = field.kind
    if kind == "bool":
        return st.sampled_from([1, 0, "true", "yes", 1.0])
    if kind == "str":
        wrong = ["", "none", 42, 1.5, False, [field.default]]
        if field.choices:
            wrong += [field.default.upper() + "x", field.default + " "]
        if _is_date(field.default):
            wrong += ["2007-13-45", "1850-01-01", "2200-06-01", "not a date", "2007-02-30"]
        return st.sampled_from(wrong)
    if kind in ("float", "int"):
        return _outside_number(field, kind == "int")
    if kind == "floats":
        good = list(field.default) or [1.0]
        element = dataclasses.replace(field, kind="float", default=_typical(good))
        n = field.length if field.length is not None else max(field.min_length, 1)
        options = [
            st.just(good[0]),  # a number, not a list
            st.just(["a"] * n),
            st.tuples(st.integers(0, n - 1), _outside_number(element, False)).map(
                lambda x: [*good[: x[0]], x[1], *good[x[0] + 1 : n]] + [good[-1]] * (n - len(good))
            ),
        ]
        if field.length is not None:
            options.append(st.sampled_from([good[:-1], good + [good[-1]], []]))
        elif field.min_length > 0:
            options.append(st.just(good[: field.min_length - 1]))
        return st.one_of(options)
    raise AssertionError(kind)


# ---- cases ----


@dataclasses.dataclass(frozen=True)
class Case:
    """One fuzz case: a system, the overrides on its example, and which were drawn outside."""

    system: str
    overrides: dict[str, Any]
    outside: tuple[str, ...] = ()

    def scenario_overrides(self) -> dict[str, Any]:
        system = gj.get_system(self.system)
        return {**system.test_overrides, **self.overrides}


@st.composite
def cases(draw, system_name: str, runtime_only: bool = False, max_fields: int = 4):
    """A :class:`Case` of ``system_name``: 1 to ``max_fields`` fields, all inside their ranges
    (half the cases), one just outside, or each inside or outside at random; a misspelt field
    one time in twenty.

    ``runtime_only`` draws inside values only for fields that reuse the compiled example
    (:func:`shape_fields`), so that a short campaign is not spent compiling.
    """
    system = gj.get_system(system_name)
    overrides: dict[str, Any] = {}
    laws = list(system.laws())
    law = system.default_law or (laws[0] if laws else None)
    if len(laws) > 1 and draw(st.booleans()):
        law = draw(st.sampled_from(laws))
        overrides["guidance.law"] = law
    fields = fields_of(system, law)
    static = shape_fields(system) if runtime_only else set()
    names = sorted(n for n in fields if n != "guidance.law")
    chosen = draw(st.lists(st.sampled_from(names), min_size=1, max_size=max_fields, unique=True))
    # every field inside (half the cases: these run), one outside, or each a coin toss
    mode = draw(st.sampled_from(["inside", "one outside", "mixed", "inside"]))
    wrong = []
    for i, name in enumerate(chosen):
        field = fields[name]
        out = {"inside": False, "one outside": i == 0, "mixed": draw(st.booleans())}[mode]
        if name in static or out:
            overrides[name] = draw(outside(field), label=name)
            wrong.append(name)
        else:
            overrides[name] = draw(inside(field), label=name)
    if draw(st.integers(0, 19)) == 19:
        section = names[0].rsplit(".", 1)[0]
        overrides[f"{section}.no_such_field"] = 1.0
        wrong.append(f"{section}.no_such_field")
    return Case(system_name, overrides, tuple(wrong))


# ---- one case ----


@dataclasses.dataclass
class Result:
    outcome: str  # one of OUTCOMES
    message: str = ""
    seconds: float = 0.0
    compile_s: float = 0.0
    failed_by_status: dict = dataclasses.field(default_factory=dict)
    stage: str = ""  # load, run or summary: where it ended


def _finite(value) -> bool:
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return all(_finite(v) for v in value)
    if isinstance(value, (float, np.floating)):
        return bool(np.isfinite(value))
    return True


def _names_a_field(message: str, system, case: Case) -> bool:
    """A refusal's first word is a field (``section.field``), a section, a study argument, or a
    drawn override's key."""
    head = message.split(":", 1)[0].strip()
    head = head.split(" ")[0]
    names = {f"{s}.{n}" for s, table in system.schema().items() for n in table}
    names |= set(system.schema())
    names |= {n.split(".")[0] for n in names} | set(case.overrides)
    names |= {"runs", "seed", "chunk_size", "max_hours", "max_memory_fraction", "cost", "scenario"}
    return head in names or any(head.startswith(n + ".") for n in names)


def check_study(study) -> Result:
    """Classify a finished study and check its bookkeeping (see ``OUTCOMES``)."""
    status = study.outcomes["status"]
    ok = status == gj.Status.ok
    valid = {int(s) for s in gj.Status}
    summary = study.summary()
    problems = []
    if not set(np.unique(status).tolist()) <= valid:
        problems.append(f"unknown status codes {sorted(set(np.unique(status).tolist()) - valid)}")
    if summary["failed"] != int(np.sum(~ok)):
        problems.append(f"failed = {summary['failed']}, non-ok runs = {int(np.sum(~ok))}")
    if sum(summary["failed_by_status"].values()) != summary["failed"]:
        problems.append(f"failed_by_status {summary['failed_by_status']} != {summary['failed']}")
    for name, values in study.outcomes.items():
        if np.issubdtype(values.dtype, np.floating):
            finite = np.isfinite(values.reshape(len(values), -1)).all(axis=1)
            if np.any(ok & ~finite):
                problems.append(f"an ok run has a non-finite {name}")
    stats = {k: v for k, v in summary.items() if k != "paper"}
    bad = sorted(k for k, v in stats.items() if not _finite(v))
    failed = dict(summary["failed_by_status"])
    if bad:
        return Result("nan_stats", f"non-finite statistics: {', '.join(bad)}", 0.0, 0.0, failed)
    if problems:
        return Result("invariant", "; ".join(problems), 0.0, 0.0, failed)
    return Result("flagged" if summary["failed"] else "ran", "", 0.0, 0.0, failed)


def run_case(case: Case, runs: int = RUNS, max_hours: float = MAX_HOURS) -> Result:
    """Load, run and classify one case; never raises."""
    t0 = time.perf_counter()
    system = gj.get_system(case.system)
    stage = "load"
    try:
        scenario = gj.load_scenario(system.example, overrides=case.scenario_overrides())
        stage = "run"
        study = gj.run_study(
            scenario, runs=runs, seed=0, chunk_size=RUNS, progress=False, max_hours=max_hours
        )
        stage = "summary"
        result = check_study(study)
        result.compile_s = study.compile_s
    except gj.ScenarioError as error:
        message = str(error)
        if "\n" in message or not message.strip():
            result = Result("invariant", f"refusal not one line: {message!r}")
        elif not _names_a_field(message, system, case):
            result = Result("invariant", f"refusal names no field: {message}")
        else:
            result = Result("refused", message)
    except Exception as error:  # the property: nothing but ScenarioError may escape
        tb = traceback.extract_tb(error.__traceback__)
        inside_pkg = [f for f in tb if "/gnc_jax/" in f.filename]
        where = inside_pkg[-1] if inside_pkg else tb[-1]
        origin = f"{where.filename.split('/gnc_jax/')[-1]}:{where.lineno} in {where.name}"
        first = str(error).splitlines()[0][:300] if str(error) else ""
        result = Result("traceback", f"{type(error).__name__}: {first} [{origin}]")
    result.seconds = time.perf_counter() - t0
    result.stage = stage
    return result
