"""Reliability of the capsule system: inputs the models cannot handle are refused in
one line before the reference design, and degraded runs are statuses, never ``ok``."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from entry_problem import design_problem

import gnc_jax as gj
from gnc_jax import cli
from gnc_jax._status import Status
from gnc_jax.guidance.entry import cache, design, nominal, reach
from gnc_jax.systems.capsule import envelope as capsule_envelope


@pytest.fixture(scope="module")
def paper():
    return gj.load_scenario("lunar-skip-entry")


def _one_line(e) -> str:
    text = str(e.value)
    assert "\n" not in text
    return text


@pytest.fixture
def no_design(monkeypatch, tmp_path):
    """An empty reference cache, and a design that fails the test if it is reached."""
    monkeypatch.setenv("GNC_JAX_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "_MEMORY", {})

    def refuse(*args, **kwargs):
        raise AssertionError("the reference design ran for an input that must be refused")

    monkeypatch.setattr(design, "design", refuse)


@pytest.mark.parametrize(
    "override, field",
    [("entry.fpa_deg=-30", "entry.fpa_deg"), ("entry.range_km=20000", "entry.range_km")],
)
def test_inputs_outside_the_declared_domain_are_refused_on_load(paper, override, field):
    with pytest.raises(gj.ScenarioError) as e:
        paper.with_overrides([override])
    assert _one_line(e).startswith(f"{field}: ")
    assert "allowed" in str(e.value)


def test_entry_above_the_skip_out_altitude_is_refused(paper):
    with pytest.raises(gj.ScenarioError) as e:
        paper.with_overrides(
            ["entry.altitude_km=150", "guidance.skip_entry.skip_out_altitude_km=140"]
        )
    assert _one_line(e).startswith("guidance.skip_entry.skip_out_altitude_km: 140 km")


def _design_banks_deg(step_deg):
    """The design's first-entry banks (its bounds) every ``step_deg``."""
    lo, hi = np.degrees(nominal.SIGMA_1_BOUNDS_RAD)
    return np.arange(lo, hi + 0.01, step_deg)


@jax.jit
def _landed_on_grid(problem, range_km, s1, s2):
    def fly(s1, s2):
        f = nominal.fly_nominal(problem, s1, s2, s2, nominal.V_SWITCH_INIT_MPS)
        skipped = (f.phase == 2) & (f.t_switch < f.t_chute) & f.done
        return jnp.where(skipped, range_km + nominal.range_error_m(problem, f) / 1e3, jnp.nan)

    return jax.vmap(fly)(s1, s2)


def _landed_ranges_km(problem, range_km, sigma_1_deg, sigma_2_deg):
    """Brute force: chute range (km, along the entry -> target track) of every nominal on a
    grid of constant first- and second-entry banks that skips and lands (NaN otherwise). The
    problem is an argument of the compiled grid: another problem on a grid of the same size
    flies on the same program."""
    s1, s2 = np.meshgrid(np.radians(sigma_1_deg), np.radians(sigma_2_deg), indexing="ij")
    range_km = jnp.asarray(range_km, dtype=jnp.float64)
    return np.asarray(
        _landed_on_grid(problem, range_km, jnp.asarray(s1.ravel()), jnp.asarray(s2.ravel()))
    )


def test_unreachable_range_is_refused_before_the_design_with_the_reachable_interval(
    paper, no_design
):
    scenario = paper.with_overrides(["entry.range_km=14000"])
    with pytest.raises(gj.ScenarioError) as e:
        gj.build(scenario)
    text = _one_line(e)
    assert text.startswith("entry.range_km: 14000 km; allowed: ")
    lo, hi = (float(x) for x in text.split("allowed: ")[1].split(" km")[0].split(" .. "))
    # a brute-force grid of the design's banks (0.5 deg first entry) lands inside the quoted
    # interval and never near the refused range
    landed = _landed_ranges_km(
        design_problem(scenario),
        14000.0,
        _design_banks_deg(0.5),
        np.degrees(reach.profile_bank_span()),
    )
    landed = landed[np.isfinite(landed)]
    assert landed.size > 0
    assert landed.min() >= lo - 1.0 and landed.max() <= hi + 1.0
    assert landed.max() > 0.5 * hi  # the interval is not a loose bound
    assert hi < 14000.0


def test_uncaptured_entry_angle_is_refused_before_the_design_with_the_corridor(
    paper, no_design, tmp_path, monkeypatch, capsys
):
    # The reach check's refusal is computed once: the command line's check, asked about the
    # same entry and vehicle sections, raises the refusal the API's check raised.
    real, refusals = cache.require_reachable, []

    def computed_once(problem, entry, vehicle, guess=None):
        for asked, refusal in refusals:
            if asked == (entry, vehicle, guess):
                raise refusal
        try:
            return real(problem, entry, vehicle, guess)
        except gj.ScenarioError as refusal:
            refusals.append(((entry, vehicle, guess), refusal))
            raise

    monkeypatch.setattr(cache, "require_reachable", computed_once)
    scenario = paper.with_overrides(["entry.fpa_deg=-4.5"])
    out = tmp_path / "study"
    with pytest.raises(gj.ScenarioError) as e:
        gj.run_study(scenario, runs=2, out=out)
    assert not out.exists()  # refused before the study directory is written: none to resume
    text = _one_line(e)
    capsys.readouterr()
    argv = ["run", "lunar-skip-entry", "--runs", "2", "--out", str(out)]
    assert cli.main([*argv, "--set", "entry.fpa_deg=-4.5"]) == cli.EXIT_REFUSED
    assert capsys.readouterr().err.splitlines()[-1] == f"gnc-jax: error: {text}"
    assert len(refusals) == 1  # the command line asked about the same sections
    assert not out.exists()  # nor the directory the command created for it
    assert text.startswith("entry.fpa_deg: -4.5 deg; the nominal flight skips out")
    shallow, steep = (float(x) for x in text.split("allowed: ")[1].split(" deg")[0].split(" .. "))
    assert steep < shallow < -4.5
    landed = _landed_ranges_km(
        design_problem(scenario),
        8000.0,
        _design_banks_deg(2.0),
        np.degrees(reach.profile_bank_span()),
    )
    assert not np.isfinite(landed).any()  # brute force: nothing skips and lands
    # and the shallow end of the quoted corridor does
    inside = paper.with_overrides([f"entry.fpa_deg={shallow}"])
    landed = _landed_ranges_km(
        design_problem(inside),
        8000.0,
        _design_banks_deg(2.0),
        np.degrees(reach.profile_bank_span()),
    )
    assert np.isfinite(landed).any()


def test_an_entry_too_steep_for_the_load_limit_is_refused_before_the_design(paper, no_design):
    """At -7.5 deg the nominal capsule's full-lift-up flight already peaks above 10 g: no bank
    keeps a run within the limit, so the entry is refused in one line naming entry.fpa_deg,
    with the corridor's undershoot boundary as the envelope pre-check computes it; a flight
    at that boundary stays within the limit. Allowed 12 g, the same entry passes the check."""
    steep = paper.with_overrides(["entry.fpa_deg=-7.5", "entry.range_km=3000"])
    with pytest.raises(gj.ScenarioError) as e:
        gj.build(steep)
    text = _one_line(e)
    assert text.startswith("entry.fpa_deg: -7.5 deg; allowed: ") and "overload" in text
    env = capsule_envelope.entry_envelope(steep.config)
    boundary = env.corridor(-12.0, -2.0, 0.05).undershoot_deg
    assert f"allowed: {boundary:.2f} deg or shallower" in text
    loads = env.flights([-7.5, boundary], [0.0]).peak_load_g[:, 0]
    assert loads[0] > 10.0 >= loads[1]
    capsule_envelope.require_within_load_limit(
        steep.with_overrides(["simulation.load_limit_g=12"]).config
    )


def test_a_design_that_misses_the_target_is_refused(paper):
    problem = design_problem(paper)
    # a design whose first-entry bank is not the root: its nominal lands far from the target
    wrong = design.DesignResult(math.radians(80.0), 1.0472, 1.0472, 7300.0, [])
    flight = nominal.fly_nominal(
        problem, wrong.sigma_1, wrong.sigma_a, wrong.sigma_b, wrong.v_switch
    )
    assert abs(float(nominal.range_error_m(problem, flight))) > 1e5
    with pytest.raises(gj.ScenarioError) as e:
        design.require_design(problem, wrong, paper.config["entry"], paper.config["vehicle"])
    assert _one_line(e).startswith("entry.range_km: 8000 km; the reference design did not")


def test_the_fine_first_guess_at_the_overshoot_boundary_brackets_a_falling_root():
    # -5.3 deg: the banks that skip and land span 118.1..120.6 deg (less than the design's
    # 2 deg step) and the chute range is not monotone there; the fallback's guess lies on the
    # falling branch next to the root (118.25 deg at 6000 km with the initial profile)
    sc = gj.load_scenario(
        "lunar-skip-entry", overrides=["entry.fpa_deg=-5.3", "entry.range_km=6000"]
    )
    problem = design_problem(sc)
    guess = design.fine_first_entry_guess(problem)
    assert guess is not None and 118.0 < math.degrees(guess) < 118.5
    a = nominal.PROFILE_INIT_RAD[0]
    ends = [guess - design.SIGMA_1_FINE_STEP_RAD, guess, guess + design.SIGMA_1_FINE_STEP_RAD]
    flights = [nominal.fly_nominal(problem, s, a, a, nominal.V_SWITCH_INIT_MPS) for s in ends]
    assert all(int(nominal.fate_of(f)) == nominal.SKIP_LANDS for f in flights[1:])
    err = [float(nominal.range_error_m(problem, f)) for f in flights]
    assert err[1] > 0.0 > err[2] or err[0] > 0.0 > err[1]


def test_the_reach_check_looks_again_on_a_fine_grid_at_the_overshoot_boundary(monkeypatch):
    # -5.3 deg: the banks that skip and land span 118.1..120.6 deg. With coarse candidates 7 deg
    # apart (74 + 7k: 116, 123) none skips and lands; the reach check's second look, on its
    # 0.25 deg grid, finds the window and returns a first guess inside it. With that look as
    # coarse as 6 deg (111, 117, 123) the entry is refused, as every such cell was before.
    sc = gj.load_scenario(
        "lunar-skip-entry", overrides=["entry.fpa_deg=-5.3", "entry.range_km=6000"]
    )
    problem = design_problem(sc)
    entry, vehicle = sc.config["entry"], sc.config["vehicle"]
    monkeypatch.setattr(reach, "SIGMA_1_STEP_RAD", math.radians(7.0))
    coarse = reach.candidate_banks()
    assert not np.any((coarse > math.radians(118.0)) & (coarse < math.radians(120.7)))
    lo, hi, guess = reach.require_reachable(problem, entry, vehicle)
    assert 118.0 < math.degrees(guess) < 120.7
    assert lo < 6000.0 < hi
    monkeypatch.setattr(reach, "SIGMA_1_REACH_FINE_STEP_RAD", math.radians(6.0))
    with pytest.raises(gj.ScenarioError) as e:
        reach.require_reachable(problem, entry, vehicle)
    assert _one_line(e).startswith("entry.fpa_deg: -5.3 deg; the nominal flight never both")


def _miss_km(o):
    return np.maximum(np.abs(o["downrange_err_km"]), np.abs(o["crossrange_err_km"]))


def test_a_miss_or_a_load_beyond_its_limit_reads_failed_outside_the_statistics(paper):
    study = gj.run_study(paper, runs=4, progress=False)
    assert (study.status == Status.ok).all()
    miss = _miss_km(study.outcomes)
    limit = float(np.median(miss))  # half of the runs miss by more
    tight = gj.run_study(
        paper.with_overrides([f"simulation.miss_limit_km={limit}"]), runs=4, progress=False
    )
    np.testing.assert_array_equal(
        tight.outcomes["downrange_err_km"], study.outcomes["downrange_err_km"]
    )
    expected = np.where(miss > limit, Status.missed, Status.ok)
    np.testing.assert_array_equal(tight.status, expected)
    s = tight.summary()
    assert s["failed"] == int((miss > limit).sum()) > 0
    ok = miss <= limit
    np.testing.assert_allclose(
        s["downrange_err_km"]["mean"], np.mean(study.outcomes["downrange_err_km"][ok])
    )
    # a run whose peak load exceeds the capsule's load limit reads overload, ahead of a miss
    # (the law's predictions left without their margin to the limit, so that the runs fly as
    # before: the margin is tested in tests/guidance/entry/test_load_relief.py)
    load = study.outcomes["load_peak_g"]
    limit_g = float(np.median(load))
    loaded = gj.run_study(
        paper.with_overrides(
            [
                f"simulation.load_limit_g={limit_g}",
                "guidance.skip_entry.predictor_load_fraction=100",
            ]
        ),
        runs=4,
        progress=False,
    )
    np.testing.assert_array_equal(loaded.outcomes["load_peak_g"], load)
    np.testing.assert_array_equal(loaded.status, np.where(load > limit_g, Status.overload, 0))
    assert loaded.summary()["failed_by_status"] == {"overload": int((load > limit_g).sum())}
    # the cost model's predictor term against the predictor steps the runs logged
    system = paper.system
    cfg = paper.config
    truth = float(np.mean(study.outcomes["t_chute_s"])) / cfg["simulation"]["dt_s"]
    predicted = system.steps_per_run(cfg) - truth
    logged = float(np.mean(study.outcomes["predictor_steps"]))
    assert predicted == pytest.approx(logged, rel=2.0)  # within x3


@pytest.mark.parametrize(
    "overrides, status",
    [
        # lift held up for the whole flight (guidance never starts): skips out of the atmosphere
        (
            [
                "guidance.hold_bank_deg=0",
                "guidance.skip_entry.hold_bank=scenario",
                "guidance.skip_entry.ng0_g=5",
            ],
            Status.skip_out,
        ),
        # the seed's corrector (eq. 15 bracketing), which cannot reach a 1 m tolerance in 3
        # predictions (the secant start sometimes can, in the last cycles)
        (
            [
                "guidance.skip_entry.corrector_start=bracket",
                "guidance.skip_entry.n_bracket=1",
                "guidance.skip_entry.n_iter=1",
                "guidance.skip_entry.range_tolerance_km=0.001",
            ],
            Status.no_convergence,
        ),
        # a corrector saturated at its smallest bank (100 deg, lift down) in every cycle: the
        # runs dive beyond the capsule's 10 g load limit, which takes precedence over the miss
        (["guidance.skip_entry.bank_min_deg=100"], Status.overload),
        # allowed the load, they cannot reach the target and land beyond the delivery
        # tolerance, which takes precedence over the failed corrector
        (["guidance.skip_entry.bank_min_deg=100", "simulation.load_limit_g=100"], Status.missed),
    ],
)
def test_degraded_runs_never_read_ok(paper, overrides, status):
    # 4 runs, as in the test above: a bank bound is an argument of that compiled study
    scenario = paper.with_overrides(overrides)
    study = gj.run_study(scenario, runs=4, progress=False)
    np.testing.assert_array_equal(study.status, status)
    assert study.summary()["failed"] == 4
    o = study.outcomes
    if status != Status.skip_out:  # every corrector cycle failed; the load or miss decides
        np.testing.assert_array_equal(o["corrector_failures"], o["pc_cycles"])
        limits = scenario.config["simulation"]
        beyond = _miss_km(o) > limits["miss_limit_km"]
        np.testing.assert_array_equal(beyond, status != Status.no_convergence)
        overloaded = o["load_peak_g"] > limits["load_limit_g"]
        np.testing.assert_array_equal(overloaded, status == Status.overload)
