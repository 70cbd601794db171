"""Short fuzz campaign, run in CI: every registered system, scenarios
drawn from its declared field ranges and from just outside them (``tests/fuzzing.py``).

Each case runs in a worker process (``tests/fuzz_campaign.py``) with a time limit, so a hang
fails the test instead of stalling CI. Inside values are drawn only for fields that reuse the
example's compiled program (``fuzzing.shape_fields``): compilation would dominate otherwise;
the long campaign (``python tests/fuzz_campaign.py``) draws every field. ``derandomize=True``:
CI draws the same cases on every run (a failure reproduces); shrinking is off because a case
is already at most four overrides, each a reproducer, and every shrink step can compile.
"""

import json

import pytest
from fuzz_campaign import Worker
from fuzzing import FAILURES, Case, cases, run_case
from hypothesis import HealthCheck, Phase, example, given, settings

import gnc_jax as gj

TIME_LIMIT_S = 240.0  # per case: the first case of a family compiles its example
EXAMPLES = {"midcourse": 20, "capsule": 20}  # the slowest to run; others: DEFAULT_EXAMPLES
DEFAULT_EXAMPLES = 40
CI_FRACTION = 2  # CI draws half as many cases; --paper-scale draws them all
MAX_FIELDS = 3


@pytest.fixture(scope="module")
def worker(tmp_path_factory):
    w = Worker(tmp_path_factory.mktemp("fuzz") / "worker.log")
    yield w
    w.stop()


def _settings(name, full):
    examples = EXAMPLES.get(name, DEFAULT_EXAMPLES)
    return settings(
        max_examples=examples if full else examples // CI_FRACTION,
        derandomize=True,
        deadline=None,
        database=None,
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )


@pytest.mark.parametrize("name", list(gj.systems()))
@pytest.mark.slow
def test_fuzzed_scenarios_run_flag_or_refuse(name, worker, paper_scale):
    outcomes = []

    @_settings(name, paper_scale)
    @given(case=cases(name, runtime_only=True, max_fields=MAX_FIELDS))
    @example(case=Case(name, {}))  # the example itself: compiles the program the draws reuse
    def check(case):
        result = worker.run(case, TIME_LIMIT_S)
        outcomes.append(result.outcome)
        print(f"{name} {result.outcome} {result.seconds:.1f} s {json.dumps(case.overrides)}")
        assert result.outcome not in FAILURES, (
            f"{name} {json.dumps(case.overrides)}: {result.outcome}: {result.message}"
        )

    check()
    drawn = outcomes[1:]  # after the explicit example
    # a campaign that only ever refuses (or only runs) tests half the property
    assert "refused" in drawn and {"ran", "flagged"} & set(drawn), drawn


def test_the_harness_sees_failures(monkeypatch):
    """The classification is not vacuous: a traceback, a NaN statistic, an unflagged
    non-finite run and a refusal of several lines are each caught."""
    system = gj.get_system("toy-intercept")
    case = Case("toy-intercept", {"guidance.pn.n": 4.0})
    assert run_case(case).outcome == "ran"

    def boom(*args, **kwargs):
        raise ZeroDivisionError("boom")

    with monkeypatch.context() as m:
        m.setattr(type(system), "statistics", boom)
        result = run_case(case)
        assert result.outcome == "traceback" and "ZeroDivisionError: boom" in result.message

    with monkeypatch.context() as m:
        m.setattr(type(system), "statistics", lambda self, o, ok: {"miss_rms_m": float("nan")})
        assert run_case(case).outcome == "nan_stats"

    with monkeypatch.context() as m:
        import gnc_jax.montecarlo as mc
        import gnc_jax.study as study

        m.setattr(study, "_nan_to_status", lambda outcomes: None)
        original = type(system).simulate

        def poisoned(self, params, law, key, record=False):
            out, trace = original(self, params, law, key, record)
            return out._replace(dispersion_m=out.dispersion_m * float("nan")), trace

        m.setattr(type(system), "simulate", poisoned)
        mc._COMPILED.clear()
        result = run_case(case)
        assert result.outcome == "invariant" and "non-finite dispersion_m" in result.message
    mc._COMPILED.clear()

    def two_lines(*args, **kwargs):
        raise gj.ScenarioError("geometry.range_m: bad\nsecond line")

    with monkeypatch.context() as m:
        m.setattr(type(system), "check", two_lines)
        assert run_case(case).outcome == "invariant"

    assert run_case(Case("toy-intercept", {"guidance.dt_s": -1.0})).outcome == "refused"


def test_a_hang_is_killed_and_the_worker_restarted(tmp_path):
    """A case over the time limit comes back as ``hang`` and the next case still runs."""
    w = Worker(tmp_path / "worker.log")
    try:
        slow = Case("toy-intercept", {"guidance.pn.n": 4.0})
        assert w.run(slow, timeout=0.05).outcome == "hang"  # its compilation alone takes ~1 s
        assert w.run(Case("toy-intercept", {"guidance.dt_s": -1.0}), 120.0).outcome == "refused"
        assert w.started == 2
    finally:
        w.stop()
