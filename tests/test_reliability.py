"""Every input is refused in one line or run to an honest outcome.

Each case found by trying the package as a new user would (hostile or unusual input to
``run``, ``reproduce`` and ``report``) is a regression test here: the refusal names the field,
the value and what is allowed, and comes before the reference design or any compilation; a
run that leaves its model's domain is a failure status, never ``ok``. The capsule's cases are
in ``systems/capsule/test_reliability.py``, midcourse and intercept in
``systems/test_reliability_midcourse_intercept.py``, random scenarios in ``test_fuzz.py``.
"""

import json
import pathlib
import shutil

import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax import cli, montecarlo
from gnc_jax import study as study_module
from gnc_jax.scenario import ScenarioError

TOY = pathlib.Path(__file__).with_name("toy.toml")

ZERO_ERRORS = {
    **{
        f"errors.{k}": 0.0
        for k in (
            "delivery_position_km",
            "image_processing_urad",
            "attitude_control_urad",
            "attitude_bias_urad",
            "attitude_noise_urad",
            "accel_bias_ug",
            "accel_noise_ug",
            "burn_magnitude_pct",
        )
    },
    "navigation.knowledge_position_km": [0.0, 0.0, 0.0],
    "navigation.knowledge_velocity_mps": 0.0,
}


def refused(argv, capsys, monkeypatch) -> str:
    """Run the CLI expecting a refusal before anything is built or compiled; its one line."""

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled or built before refusing")

    monkeypatch.setattr(montecarlo, "build", no_compile)
    monkeypatch.setattr(montecarlo, "_compile", no_compile)
    assert cli.main(argv) == cli.EXIT_REFUSED
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("gnc-jax: error: "), err
    return err


# ---- tracebacks that became one line -------------------------------------------------------


def test_a_toml_that_is_not_utf8_is_refused(tmp_path, capsys, monkeypatch):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'[scenario]\nkind = "impactor"\nname = "caf\xe9"\n')
    err = refused(["run", str(path)], capsys, monkeypatch)
    assert "not UTF-8 text" in err and "latin1.toml" in err


@pytest.mark.parametrize(
    "text, message",
    [
        ("scenario = 5\n", "scenario: expected a table [scenario], got 5"),
        ('paper = "x"\n[scenario]\nkind = "impactor"\n', "paper: expected a table [paper]"),
        ('[scenario]\nkind = "impactor"\nseed = 4294967296\n', "scenario.seed: 4294967296"),
        ('[scenario]\nkind = "impactor"\nruns = 0\n', "scenario.runs: 0"),
    ],
)
def test_a_malformed_scenario_table_is_refused(tmp_path, capsys, monkeypatch, text, message):
    path = tmp_path / "user.toml"
    path.write_text(text)
    assert message in refused(["run", str(path)], capsys, monkeypatch)


def test_the_loader_and_run_accept_the_same_seeds(tmp_path):
    top = 2**32 - 1
    for seed, ok in ((top, True), (top + 1, False), (-1, False)):
        path = tmp_path / "user.toml"
        path.write_text(f'[scenario]\nkind = "impactor"\nseed = {seed}\n')
        try:
            gj.load_scenario(path)
            loads = True
        except ScenarioError:
            loads = False
        try:
            cli._seed(str(seed))
            parses = True
        except Exception:
            parses = False
        assert loads == parses == ok, seed


@pytest.mark.parametrize(
    "setting, message",
    [
        ("approach.position_km=[1e200,0,0]", "approach.position_km: 1e+200 is out of range"),
        ("approach.velocity_kmps=[1e-300,0,0]", "approach.velocity_kmps: speed 1e-300 km/s"),
        ("approach.reference_normal=[0,0,1e-300]", "approach.reference_normal: [0.0, 0.0, 1e-300]"),
        ("dynamics.sun_direction=[1e-300,0,0]", "dynamics.sun_direction: [1e-300, 0.0, 0.0]"),
        ("dynamics.sun_distance_au=1e-300", "dynamics.sun_distance_au: 1e-300 AU"),
        ("guidance.dt_s=0.0001", "guidance.dt_s: 0.0001 is out of range"),
        ("approach.position_km=[1e9,0,0]", "approach.position_km: 1000000000.0 is out of range"),
        ("spacecraft.mass_kg=1e-6", "spacecraft.propellant_kg: 25 kg is not less than"),
        ("camera.image_interval_s=3600", "camera.image_interval_s: 3600 s leaves"),
        ("spacecraft.isp_s=5e-324", "spacecraft.isp_s: 5e-324 is out of range"),
        # the aim point would change after the cut-off: the miss from an aim never flown
        ("guidance.retarget_tgo_s=10", "guidance.retarget_tgo_s: 10 s is not more than"),
    ],
)
def test_impactor_inputs_outside_the_models_domain_are_refused(
    setting, message, capsys, monkeypatch
):
    err = refused(["run", "deep-impact-los", "--runs", "2", "--set", setting], capsys, monkeypatch)
    assert message in err
    assert "allowed:" in err


def test_an_approach_beyond_the_propellant_budget_is_refused(capsys, monkeypatch):
    # Found by the fuzz campaign: an approach 104000 km off the target "burned" all 25 kg and
    # every run was flagged `propellant`; the impulsive lower bound refuses it up front.
    argv = ["run", "deep-impact-los", "--set", "approach.position_km=[73440,73440,73440]"]
    err = refused(argv, capsys, monkeypatch)
    assert "needs at least 1.44e+04 m/s, the propellant gives 157 m/s" in err
    # 157 m/s = 230 s x g0 x ln(372 / 347)
    assert 230 * 9.80665 * np.log(372 / 347) == pytest.approx(157, abs=0.5)


def test_a_slow_far_approach_is_refused_by_its_time_of_flight(capsys, monkeypatch):
    argv = ["run", "deep-impact-los", "--set", "approach.position_km=[1e7,0,0]"]
    argv += ["--set", "approach.velocity_kmps=[-1,0,0]"]
    assert "time of flight 116 days" in refused(argv, capsys, monkeypatch)
    # a start too close (9 km, beyond two of Tempel 1's 3.8 km radii): the cut-off's bound names
    # the fields the time of flight comes from
    err = refused(["run", "deep-impact-los", "--set", "approach.position_km=[9,0,0]"], capsys,
                  monkeypatch)  # fmt: skip
    assert "the time of flight of approach.position_km at approach.velocity_kmps" in err


def test_predictive_schedule_conflicts_name_both_fields(capsys, monkeypatch):
    base = ["run", "deep-impact-predictive", "--set"]
    err = refused(base + ["guidance.cutoff_tgo_s=1000"], capsys, monkeypatch)
    assert "the burn at 6450 s is not before the cut-off at 6200 s" in err
    assert "guidance.cutoff_tgo_s" in err
    err = refused(base + ["camera.image_interval_s=600"], capsys, monkeypatch)
    assert err.startswith("gnc-jax: error: camera.image_interval_s: 600 s is longer than")
    # The LOS law has no burn times: the same camera interval is fine for it.
    gj.load_scenario("deep-impact-los", {"camera.image_interval_s": 600.0})


def test_a_retarget_after_the_last_scheduled_burn_is_refused(capsys, monkeypatch):
    # Found trying other approaches: at 2 km/s from 30000 km the default burn schedule ends
    # 7500 s before the retarget, and every run "hit" 3.2 km from the new aim point, all ok.
    argv = ["run", "deep-impact-predictive", "--set", "approach.velocity_kmps=[-2,0,0]"]
    argv += ["--set", "approach.position_km=[30000,0,0]"]
    err = refused(argv, capsys, monkeypatch)
    assert "guidance.retarget_tgo_s: the aim point changes at 14250 s" in err
    assert "after the last burn of guidance.predictive.burn_times_s (6780 s)" in err


def test_a_change_of_aim_point_after_the_cutoff_is_refused_and_none_is_accepted():
    at_cutoff = {"guidance.retarget_tgo_s": 60.0}
    with pytest.raises(ScenarioError, match=r"allowed: \(60, 7200\) s, or aim_final_km"):
        gj.load_scenario("deep-impact-los", at_cutoff)
    # with one aim point the retarget time changes nothing
    gj.load_scenario("deep-impact-los", {**at_cutoff, "guidance.aim_final_km": [0.0, 0.0]})


def test_a_control_step_past_the_nominal_impact_is_refused():
    # 73445.1 km at 10.2 km/s: impact at 7200.5 s; with no cut-off the control step that
    # starts at 7200 s ends at 7201 s, 5 km past the B-plane.
    past = {"approach.position_km": [73445.1, 0.0, 0.0], "guidance.cutoff_tgo_s": 0.0}
    with pytest.raises(
        ScenarioError, match=r"guidance.cutoff_tgo_s: 0 s .* allowed: at least 0.5 s"
    ):
        gj.load_scenario("deep-impact-los", past)
    gj.load_scenario("deep-impact-los", {**past, "guidance.cutoff_tgo_s": 0.5})


def test_a_burn_at_the_retarget_time_of_a_rounded_time_of_flight_is_accepted():
    # 73440 km / 10.2 km/s = 7200.000000000001 s: the retarget at t_go = 750 s is the burn at
    # 6450 s, as the simulation's times (rounded to 1 us) have it.
    schedule = "guidance.predictive.burn_times_s"
    sc = gj.load_scenario("deep-impact-predictive", {schedule: [1200.0, 4100.0, 6450.0]})
    _, law = gj.build(sc)
    assert float(law.burn_times_s[-1]) >= float(gj.build(sc)[0].context.retarget_time_s)
    # a burn before the retarget, or at the cut-off, is still refused
    with pytest.raises(ScenarioError, match="after the last burn"):
        gj.load_scenario("deep-impact-predictive", {schedule: [1200.0, 4100.0, 6449.9999]})
    with pytest.raises(ScenarioError, match="the burn at 7140 s is not before the cut-off"):
        gj.load_scenario("deep-impact-predictive", {schedule: [1200.0, 4100.0, 6450.0, 7140.0]})


# ---- runaway cost ---------------------------------------------------------------------------


def test_ten_billion_runs_are_refused_with_the_estimate(capsys, monkeypatch):
    err = refused(["run", "deep-impact-los", "--runs", "10000000000"], capsys, monkeypatch)
    assert "cost: 10000000000 runs x" in err and "days on" in err and "--max-hours" in err


def test_the_cost_estimate_is_computed_from_the_scenario_alone():
    scenario = gj.load_scenario("deep-impact-los")
    one = gj.estimate_cost(scenario, runs=1000)
    fine = gj.estimate_cost(scenario.with_overrides({"guidance.dt_s": 0.1}), runs=1000)
    # 476 images of 15 s before the cut-off; ten times the control steps per image at 0.1 s
    assert fine.steps_per_run - one.steps_per_run == pytest.approx(476 * (150 - 15))
    sim, _ = gj.build(scenario)
    assert one.steps_per_run >= sim.n_images * sim.steps_per_image
    # a throughput term in the runs plus a sequential latency term that is not
    two = gj.estimate_cost(scenario, runs=2000)
    assert two.seconds - two.latency_s == pytest.approx(2 * (one.seconds - one.latency_s))
    assert two.latency_s == one.latency_s > 0


def test_a_chunk_too_large_for_memory_is_refused_before_it_runs(monkeypatch, tmp_path):
    scenario = gj.load_scenario(TOY)
    ran = []
    real = montecarlo._joined  # every finished chunk's outcomes pass through it
    monkeypatch.setattr(montecarlo, "_joined", lambda outs: (ran.append(1), real(outs))[1])
    out = tmp_path / "study"
    with pytest.raises(
        ScenarioError, match=r"chunk_size: 1000 runs need .* allowed: chunk_size <="
    ):
        gj.run_study(scenario, runs=1000, chunk_size=1000, max_memory_fraction=1e-9, out=out)
    assert ran == []  # refused after compilation, before any chunk ran
    assert not out.exists()  # and before the study directory was written: none to resume


@pytest.mark.slow
def test_ten_million_runs_in_one_chunk_are_refused_before_they_run(paper_scale):
    # `--chunk-size 10000000` tried to allocate 12 GB. Compiling it
    # takes ~8 s; the refusal comes from the compiled program's own memory figures.
    scenario = gj.load_scenario("deep-impact-los")
    runs = 10_000_000 if paper_scale else 2_000_000
    with pytest.raises(ScenarioError, match="chunk_size: .* GB"):
        gj.run_study(
            scenario,
            runs=runs,
            chunk_size=runs,
            max_hours=1e5,
            max_memory_fraction=0.5 * (1.0 if paper_scale else 0.1),
        )


# ---- honest outcomes ------------------------------------------------------------------------


@pytest.mark.parametrize("law", ["los", "pn", "predictive"])
def test_a_zero_error_run_flies_the_nominal_trajectory_to_a_hit(law):
    # The first thing many users try: every error source and the initial knowledge at zero.
    # The run must be ok, fire once or twice for the retarget from (0, 0) to (1, 3) km, and
    # hit the aim point; the Δv of the retarget is about |Δaim| / t_go at the burn.
    base = gj.get_system("impactor").example
    scenario = gj.load_scenario(
        "deep-impact-predictive" if law == "predictive" else base,
        {**ZERO_ERRORS, "guidance.law": law},
    )
    # 300 runs in the default chunks: for the LOS and predictive laws the program
    # tests/systems/impactor/test_simulation.py::test_paper_scale_deep_impact compiles (a
    # zero-error run costs little next to a compilation)
    study = gj.run_study(scenario, runs=300, progress=False)
    assert study.summary()["failed"] == 0, study.summary()["failed_by_status"]
    o = study.outcomes
    assert np.all(o["miss_m"] < 10.0), o["miss_m"]
    assert np.all(o["firings"] <= 2)
    aim_change = np.hypot(1e3, 3e3)
    assert np.all(o["dv_mps"] < 2.0 * aim_change / 750.0), o["dv_mps"]


def test_a_run_that_needs_more_propellant_than_it_carries_is_flagged():
    scenario = gj.load_scenario(
        "deep-impact-los",
        {**gj.get_system("impactor").test_overrides, "spacecraft.propellant_kg": 0.05},
    )
    study = gj.run_study(scenario, runs=8, chunk_size=4, progress=False)  # the family's program
    s = study.summary()
    used = study.outcomes["fuel_kg"]
    flagged = study.status == gj.Status.propellant
    np.testing.assert_array_equal(flagged, used > 0.05)
    assert flagged.any() and s["failed"] == flagged.sum()
    assert s["failed_by_status"]["propellant"] == flagged.sum()


# ---- exit codes -----------------------------------------------------------------------------


def test_exit_code_follows_the_failed_fraction(tmp_path, capsys, monkeypatch):
    system = gj.get_system("toy-intercept")
    import jax.numpy as jnp

    class HalfNaN(type(system)):
        def simulate(self, params, law, key, record=False):
            out, trace = super().simulate(params, law, key, record)
            bad = jnp.asarray(out.miss_m).astype(jnp.int64) % 2 == 0  # about half the runs
            return out._replace(miss_m=jnp.where(bad, jnp.nan, out.miss_m)), trace

    monkeypatch.setattr(montecarlo, "get_system", lambda kind: HalfNaN())
    monkeypatch.setattr(study_module, "get_system", lambda kind: HalfNaN())
    argv = ["run", str(TOY), "--runs", "20", "--no-progress", "--out", str(tmp_path / "a")]
    assert cli.main(argv) == cli.EXIT_FAILED_RUNS
    err = capsys.readouterr().err
    assert "runs failed" in err and "more than --max-failed 0.01" in err
    assert (tmp_path / "a" / "summary.json").is_file()  # written before the exit code
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert 0 < summary["failed"] < 20
    assert cli.main(argv + ["--max-failed", "0.9", "--overwrite"]) == 0


# ---- report on damaged results --------------------------------------------------------------


@pytest.fixture(scope="module")
def toy_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("toy") / "study"
    study = gj.run_study(gj.load_scenario(TOY), runs=20, progress=False)
    study.save(out)
    return out


@pytest.mark.parametrize(
    "damage, message",
    [
        (
            lambda d: (d / "summary.json").write_text('{"scenario": "x", "ru'),
            "summary.json: not valid JSON",
        ),
        (
            lambda d: (d / "summary.json").write_text("[1, 2]"),
            "summary.json: not a gnc_jax summary",
        ),
        (
            lambda d: (d / "runs" / "chunk-000000.parquet").write_bytes(
                (d / "runs" / "chunk-000000.parquet").read_bytes()[:300]
            ),
            "chunk-000000.parquet: not a readable Parquet file",
        ),
        (lambda d: (d / "scenario.toml").write_text("kind = ["), "scenario.toml: scenario"),
        (lambda d: shutil.rmtree(d / "runs"), "runs: missing"),
    ],
)
def test_report_on_a_damaged_directory_names_the_file(
    toy_results, tmp_path, capsys, damage, message
):
    d = tmp_path / "copy"
    shutil.copytree(toy_results, d)
    damage(d)
    assert cli.main(["report", str(d)]) == cli.EXIT_REFUSED
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def test_report_on_a_partial_runs_file_says_so(toy_results, tmp_path, capsys):
    import pyarrow.parquet as pq

    d = tmp_path / "copy"
    shutil.copytree(toy_results, d)
    chunk = d / "runs" / "chunk-000000.parquet"
    pq.write_table(pq.read_table(chunk).slice(0, 5), chunk)
    assert cli.main(["report", str(d)]) == cli.EXIT_REFUSED
    assert "5 rows, but summary.json says 20 runs" in capsys.readouterr().err


# ---- a bug is one line too ------------------------------------------------------------------


def test_an_internal_error_is_one_line_with_a_way_to_the_traceback(capsys, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(study_module, "run_study", broken)
    monkeypatch.delenv(cli.DEBUG_ENV, raising=False)
    assert cli.main(["run", "deep-impact-los", "--runs", "2"]) == cli.EXIT_INTERNAL
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "internal error: RuntimeError: boom" in err and cli.DEBUG_ENV in err
    monkeypatch.setenv(cli.DEBUG_ENV, "1")
    with pytest.raises(RuntimeError):
        cli.main(["run", "deep-impact-los", "--runs", "2"])


def test_a_long_study_announces_its_estimate_and_runs_in_chunks_with_progress(capsys, monkeypatch):
    scenario = gj.load_scenario(TOY)
    system = gj.get_system(scenario.kind)
    steps = system.steps_per_run(scenario.config)
    assert steps is not None
    # Pretend a step costs enough for 40 runs to take ~100 s: the study must say so up front
    # and run in chunks of about 10 s (4 runs), so that the progress bar has an ETA.
    monkeypatch.setattr(type(system), "step_seconds", 100.0 / (20 * steps))
    study = gj.run_study(scenario, runs=40, progress=None)
    err = capsys.readouterr().err
    assert "estimated 40 runs x" in err
    assert study.chunk_size == 4
    assert study.summary()["failed"] == 0


def test_device_batches_are_padded_to_whole_vectors_without_changing_a_run(monkeypatch):
    from gnc_jax.montecarlo import LANES_FROM, padded_chunk

    assert padded_chunk(1, 2, 8) == 2 and padded_chunk(7, 2, 8) == 8  # small: whole runs
    assert padded_chunk(2 * LANES_FROM - 2, 2, 8) == 2 * LANES_FROM - 2  # 63 per device
    assert padded_chunk(3334, 2, 8) == 3344 and padded_chunk(4096, 2, 8) == 4096
    assert padded_chunk(1001, 1, 8) == 1008 and padded_chunk(1001, 1) == 1001
    assert padded_chunk(3334, 2) == 3334  # a system without lanes: whole runs per device only
    # A padded study (130 runs: 65 per device -> 72) equals a loop of small, unpadded chunks.
    scenario = gj.load_scenario(TOY)
    monkeypatch.setattr(type(gj.get_system(scenario.kind)), "vector_lanes", 8)
    padded = gj.run_study(scenario, runs=130, seed=5, progress=False)
    assert padded.chunk_size == 144
    small = gj.run_study(scenario, runs=130, seed=5, chunk_size=10, progress=False)
    assert small.chunk_size == 10
    for name, x in padded.outcomes.items():
        np.testing.assert_allclose(x, small.outcomes[name], rtol=1e-12, atol=0, err_msg=name)


def test_a_report_draws_its_first_ok_run_as_the_example():
    from gnc_jax._status import Status, shown_run

    failed, ok = int(Status.propellant), int(Status.ok)
    assert shown_run(np.array([failed, failed, ok, ok])) == (2, "run 2")
    assert shown_run(np.array([ok, failed])) == (0, "run 0")
    assert shown_run(np.array([failed, int(Status.nan)])) == (0, "run 0 (propellant)")


@pytest.mark.parametrize("name", ["deep-impact-los", "bennu-apn"])
def test_a_report_traces_the_first_ok_run_of_a_study_whose_first_run_failed(name):
    """The example run a report simulates again (the impactor's engine trace and frames, the
    intercept's command trace) is the first ok run, not run 0 when run 0 failed."""
    from gnc_jax._status import Status

    scenario = gj.load_scenario(name)
    runs = {"status": np.array([int(Status.propellant), int(Status.missed), int(Status.ok)])}
    requests = gj.get_system(scenario.kind).figure_traces({}, runs, scenario)
    assert requests["shown"].indices == (2,)
