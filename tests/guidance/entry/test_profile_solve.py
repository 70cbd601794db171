"""The reference design that meets the range with the second-entry bank, against brute force
and against the nominal flights of a scan."""

import math
import re

import jax.numpy as jnp
import numpy as np
import pytest
from entry_problem import skip_entry_problem

import gnc_jax as gj
from gnc_jax.guidance.entry import design, nominal, profile_solve, reach


def _brute_force_row(err, fate):
    n, m = err.shape
    lands = [bool((fate[i] == nominal.SKIP_LANDS).all()) for i in range(n)]
    best, best_key = None, None
    for i in range(n):
        if not lands[i] or not (err[i, 0] >= 0.0 >= err[i, -1]):
            continue
        depth = min(abs(i - j) for j in [-1, n] + [j for j in range(n) if not lands[j]])
        for k in range(m - 1):  # the root of the piecewise-linear errors (falling)
            if err[i, k] >= 0.0 >= err[i, k + 1]:
                a, b = profile_solve.PROFILE_SCAN_RAD[k : k + 2]
                w = err[i, k] / (err[i, k] - err[i, k + 1]) if err[i, k] != err[i, k + 1] else 0
                key = (-depth, abs(a + w * (b - a) - math.pi / 2))
                break
        if best_key is None or key < best_key:
            best, best_key = i, key
    return best


def test_the_first_entry_bank_choice_matches_brute_force():
    rng = np.random.default_rng(3)
    m = profile_solve.PROFILE_SCAN_RAD.size
    for _ in range(200):
        n = int(rng.integers(3, 12))
        level = rng.normal(0.0, 2e6, size=(n, 1))
        err = level - np.sort(rng.uniform(0, 4e6, size=(n, m)), axis=1)  # falling in sigma_2
        err += np.linspace(1.5e6, 0.0, m)
        fate = np.where(rng.random((n, m)) < 0.1, nominal.NEVER_LANDS, nominal.SKIP_LANDS)
        assert profile_solve.choose_first_entry_bank(err, fate) == _brute_force_row(err, fate)


def test_the_reachable_intervals_are_where_the_choice_brackets_a_target():
    """A target ``d`` m beyond the scan's has a row (choose_first_entry_bank on the errors
    less ``d``) exactly when ``d`` lies in one of reachable_intervals, which are disjoint and
    increasing."""
    rng = np.random.default_rng(5)
    m = profile_solve.PROFILE_SCAN_RAD.size
    shifts = np.linspace(-7e6, 7e6, 281)
    for _ in range(100):
        n = int(rng.integers(3, 12))
        level = rng.normal(0.0, 2e6, size=(n, 1))
        err = level - np.sort(rng.uniform(0, 4e6, size=(n, m)), axis=1)
        err += np.linspace(1.5e6, 0.0, m)
        fate = np.where(rng.random((n, m)) < 0.1, nominal.NEVER_LANDS, nominal.SKIP_LANDS)
        spans = profile_solve.reachable_intervals(err, fate)
        assert all(a[1] < b[0] for a, b in zip(spans, spans[1:]))
        for d in shifts:
            found = profile_solve.choose_first_entry_bank(err - d, fate) is not None
            assert found == any(lo <= d <= hi for lo, hi in spans)


def _spans_km(text: str) -> list[tuple[float, float]]:
    """The intervals "a .. b, c .. d or e .. f km" a refusal states in its parentheses."""
    reach = re.search(r"\(([\d .,or]+) km;", text).group(1)
    return [(float(a), float(b)) for a, b in re.findall(r"(\d+) \.\. (\d+)", reach)]


@pytest.fixture(scope="module")
def boundary():
    """The packaged capsule at -5.3 deg (the overshoot boundary), 4000 km."""
    return skip_entry_problem(["entry.fpa_deg=-5.3", "entry.range_km=4000"])


def test_the_profile_design_puts_the_chute_on_a_target_no_first_entry_bank_reaches(boundary):
    problem, cfg = boundary
    # with the design's initial profile (60 deg) no first-entry bank that skips and lands
    # gets as short as 4000 km: the first-entry bank solve has no root there
    banks = np.radians(np.arange(115.0, 122.0, 0.25))
    a = nominal.PROFILE_INIT_RAD[0]
    err, fate = (
        np.asarray(x)[:, 0]
        for x in reach.candidate_flights(problem, jnp.asarray(banks), jnp.asarray([a]))
    )
    assert (fate == nominal.SKIP_LANDS).any()
    assert (err[fate == nominal.SKIP_LANDS] > 100e3).all()
    d = design.design_by_profile(problem, cfg["entry"], cfg["vehicle"])
    assert d.sigma_a == d.sigma_b
    assert nominal.PROFILE_BOUNDS_RAD[0] < d.sigma_a < nominal.PROFILE_BOUNDS_RAD[1]
    flight = nominal.fly_nominal(problem, d.sigma_1, d.sigma_a, d.sigma_b, d.v_switch)
    assert int(nominal.fate_of(flight)) == nominal.SKIP_LANDS
    assert abs(float(nominal.range_error_m(problem, flight))) < nominal.RANGE_TOLERANCE_M * 10
    design.require_design(problem, d, cfg["entry"], cfg["vehicle"])  # does not refuse
    # the chute range falls with the second-entry bank at the chosen first-entry bank, so the
    # root is the only one: 5 deg either side lands beyond and short of the target
    side = [
        float(
            nominal.range_error_m(
                problem, nominal.fly_nominal(problem, d.sigma_1, s, s, d.v_switch)
            )
        )
        for s in (d.sigma_a - math.radians(5.0), d.sigma_a + math.radians(5.0))
    ]
    assert side[0] > 0.0 > side[1]


def test_a_target_beyond_every_skip_is_refused_with_the_reachable_interval(boundary):
    problem, cfg = boundary
    far = dict(cfg["entry"], range_km=15000.0)
    problem = skip_entry_problem(["entry.fpa_deg=-5.3", "entry.range_km=15000"])[0]
    with pytest.raises(gj.ScenarioError) as e:
        design.design_by_profile(problem, far, cfg["vehicle"])
    text = str(e.value)
    assert "\n" not in text and text.startswith("entry.range_km: 15000 km; allowed:")
    spans = _spans_km(text)
    # the intervals hold the 4000 km target the same vehicle reaches (test above)
    assert any(lo < 4000.0 < hi for lo, hi in spans) and spans[-1][1] < 15000.0
    # the packaged capsule at 12000 km: inside the span of the scan's landings (1838 ..
    # 12695 km) but bracketed by no first-entry bank; the stated intervals leave it out
    problem, cfg = skip_entry_problem(["entry.range_km=12000"])
    with pytest.raises(gj.ScenarioError) as e:
        design.design_by_profile(problem, cfg["entry"], cfg["vehicle"])
    spans = _spans_km(str(e.value))
    assert spans and not any(lo <= 12000.0 <= hi for lo, hi in spans)


def test_a_target_beyond_the_designs_banks_is_designed_at_the_edge_of_the_footprint(capsys):
    """The packaged capsule at -7.1 deg reaches 10,000 km only by a lofted skip near full lift
    up (its constant-bank footprint ends at 10,083 km): the design's own first-entry banks
    refuse it, the edge design puts the chute on it with a bank below them."""
    problem, cfg = skip_entry_problem(["entry.fpa_deg=-7.1", "entry.range_km=10000"])
    with pytest.raises(gj.ScenarioError) as e:
        reach.require_reachable(problem, cfg["entry"], cfg["vehicle"])
    assert str(e.value).startswith("entry.range_km: 10000 km; allowed:")
    d = design.design_at_the_edge(problem, cfg["entry"], cfg["vehicle"], e.value)
    assert d.sigma_1 < nominal.SIGMA_1_BOUNDS_RAD[0]
    assert design.EDGE_PROFILE_BOUNDS_RAD[0] <= d.sigma_a == d.sigma_b
    flight = nominal.fly_nominal(problem, d.sigma_1, d.sigma_a, d.sigma_b, d.v_switch)
    assert int(nominal.fate_of(flight)) == nominal.SKIP_LANDS
    assert abs(float(nominal.range_error_m(problem, flight))) < design.DESIGN_MISS_LIMIT_M
    assert "designed at the edge of the footprint" in capsys.readouterr().err
    # beyond the footprint too: refused, the edge design's reach added to the refusal
    far = skip_entry_problem(["entry.fpa_deg=-7.1", "entry.range_km=12000"])[0]
    with pytest.raises(gj.ScenarioError) as e2:
        design.design_at_the_edge(
            far, dict(cfg["entry"], range_km=12000.0), cfg["vehicle"], e.value
        )
    text = str(e2.value)
    assert "\n" not in text and "second-entry banks 15..165 deg too: a range" in text
    assert text.count("allowed:") == 1  # one line, one list of what is allowed
    hi = _spans_km(text.rpartition("deg too: ")[2])[-1][1]
    assert 10000.0 < hi < 12000.0


def test_a_design_at_the_edge_says_so_again_when_its_cached_reference_is_read(
    tmp_path, monkeypatch, capsys
):
    """The reference of a design made at the footprint's edge, read back from the cache by a
    later process, repeats the edge design's notice; a standard design's says nothing."""
    from gnc_jax.guidance.entry import cache
    from gnc_jax.schema import ScenarioError

    _, law = gj.build(gj.load_scenario("lunar-skip-entry"))
    monkeypatch.setenv("GNC_JAX_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "tabulate_reference", lambda problem, d: law.reference)
    edge = design.DesignResult(0.04, 0.26, 0.26, 7000.0, [1.0])

    def refused(*_, **__):
        raise ScenarioError("entry.range_km: 12000 km; beyond the design's banks")

    monkeypatch.setattr(cache, "require_reachable", refused)
    monkeypatch.setattr(cache, "design_at_the_edge", lambda problem, entry, vehicle, e: edge)
    for range_km, notice in ((12000.0, True), (8000.0, False)):
        description = {"entry": {"range_km": range_km}, "vehicle": {}}
        if not notice:  # a standard design
            monkeypatch.setattr(cache, "require_reachable", lambda *_, **__: (0, 0, 1.3))
            monkeypatch.setattr(cache, "require_design_reach", lambda *_, **__: None)
            monkeypatch.setattr(cache, "design_with_fallback", lambda *_, **__: edge)
        cache.reference_for(None, description)
        capsys.readouterr()
        cache._MEMORY.clear()  # a later process: read from the cache
        cache.reference_for(None, description)
        said = "designed at the edge of the footprint" in capsys.readouterr().err
        assert said == notice
