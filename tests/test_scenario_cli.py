"""Scenario validation, CLI commands, results files and reports."""

import json
import math
import os
import pathlib
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
from short_impactor import SHORT

import gnc_jax as gj
from gnc_jax import cli, montecarlo
from gnc_jax import study as study_module
from gnc_jax.scenario import ScenarioError
from gnc_jax.schema import Field

BAD_INPUT = [
    (["run", "no-such-scenario"], "scenario: unknown scenario 'no-such-scenario'"),
    (["run", "deep-impact-los", "--set", "guidance.kk1=3"], "guidance.kk1: unknown field"),
    (["run", "deep-impact-los", "--set", "warp.speed=3"], "warp: unknown section"),
    (
        ["run", "deep-impact-los", "--set", 'guidance.los.k1="four"'],
        "guidance.los.k1: expected a number",
    ),
    (["run", "deep-impact-los", "--set", "guidance.k1=3"], "it moved to [guidance.los]"),
    (["run", "deep-impact-los", "--set", "guidance.los.kk=3"], "guidance.los.kk: unknown field"),
    (["run", "deep-impact-los", "--set", "guidance.law=pid"], "guidance.law: got 'pid'"),
    (["run", "deep-impact-los", "--set", "spacecraft.mass_kg=-372"], "spacecraft.mass_kg: -372"),
    (["run", "deep-impact-los", "--set", "spacecraft.thrust_n=0"], "spacecraft.thrust_n: 0"),
    (["run", "deep-impact-los", "--set", "guidance.los.k2=5"], "guidance.los.k2: 5 > k1 = 4"),
    (["run", "deep-impact-los", "--set", "guidance.dt_s=7"], "guidance.dt_s: 7 s does not divide"),
    (
        ["run", "deep-impact-los", "--set", "approach.reference_normal=[1.0,0.0,0.0]"],
        "approach.reference_normal: parallel",
    ),
    (["run", "deep-impact-los", "--runs", "0"], "--runs: '0'; allowed: an integer >= 1"),
    (["run", "deep-impact-los", "--runs", "-5"], "--runs: '-5'; allowed"),
    (["run", "deep-impact-los", "--seed", "x"], "--seed: 'x'"),
    (["run", "missing.toml"], "scenario: no such file 'missing.toml'"),
    (["run", "autonav-predictive", "--set", "camera.window_px=16"], "camera.window_px: 16"),
    (["run", "autonav-predictive", "--set", "camera.window_px=31"], "camera.window_px: 31"),
    (["run", "autonav-predictive", "--set", "navigation.measurement=pixels"], "got 'pixels'"),
    (["run", "autonav-predictive", "--set", "camera.roi_px=4"], "camera.roi_px: 4"),
    (["run", "autonav-predictive", "--set", "target.semi_axes_km=[3.0,0.0,3.0]"], "semi_axes"),
    (["run", "autonav-predictive", "--set", "camera.max_bin_log2=5"], "camera.max_bin_log2: 5"),
    (
        ["run", "autonav-predictive", "--set", "dynamics.sun_direction=[0.0,0.0,0.0]"],
        "dynamics.sun_direction: [0.0, 0.0, 0.0] has length 0; allowed: a direction",
    ),
]
BAD_INPUT.append(
    (
        ["run", "deep-impact-los", "--set", "approach.velocity_kmps=[10.2,0.0,0.0]"],
        "approach.velocity_kmps: the impactor must approach the target; allowed",
    )
)
BAD_INPUT.append(
    (
        [
            "run",
            "lunar-skip-entry",
            "--set",
            "guidance.skip_entry.bank_min_deg=170",
            "--set",
            "guidance.skip_entry.bank_max_deg=10",
        ],
        "guidance.skip_entry.bank_min_deg: 170 deg; allowed: below",
    )
)
APN = "bennu-apn"
BAD_INPUT += [
    (
        ["run", APN, "--set", "guidance.apn.trigger_off=2"],
        "guidance.apn.trigger_off: 2 >= trigger_on",
    ),
    (["run", APN, "--set", "guidance.apn.n0=-1"], "guidance.apn.n0: -1"),
    (["run", APN, "--set", "guidance.apn.k=11"], "guidance.apn.k: 11"),
    (["run", APN, "--set", "guidance.n0=3"], "it moved to [guidance.apn]"),
    (["run", APN, "--set", "spacecraft.pulse_width_s=2"], "spacecraft.pulse_width_s: 2 > guid"),
    (["run", APN, "--set", "navigation.model=kalman"], "navigation.model: got 'kalman'"),
    (["run", APN, "--set", "approach.geometry=spherical"], "approach.geometry: got"),
    (["run", APN, "--set", "guidance.coast_s=1e6"], "guidance.coast_s: 1e+06"),
    (["run", APN, "--set", "guidance.coast_s=0"], "guidance.coast_s: 0"),
    (
        ["run", APN, "--set", "navigation.image_interval_s=1.5"],
        "navigation.image_interval_s: 1.5 s is not a whole multiple",
    ),
    (
        ["run", APN, "--set", "approach.impactor_position_km=[1.34176e8, 9.36358e5, 5.0]"],
        "approach.impactor_position_km: z = 5 in a planar scenario",
    ),
    (
        ["run", APN, "--set", "approach.impactor_velocity_kmps=[0.0, 44.0, 0.0]"],
        "approach.impactor_velocity_kmps: the impactor must close",
    ),
    (["run", APN, "--set", "navigation.knowledge_position_km=[1.0, 2.0]"], "expected 3 numbers"),
    # 900 s images: 102 of them end the loop at 91800 s, past the B-plane at 91799.8 s
    (
        ["run", APN, "--set", "navigation.image_interval_s=900"],
        "navigation.image_interval_s: 900 s is longer than guidance.coast_s = 600 s",
    ),
    (
        ["run", APN, "--set", "guidance.dt_s=60", "--set", "guidance.coast_s=30"],
        "guidance.dt_s: 60 s is longer than guidance.coast_s = 30 s",
    ),
    (["run", APN, "--set", "guidance.apn.n_min=0"], "guidance.apn.n_min: 0 is out of range"),
    (["run", APN, "--set", "guidance.apn.n_min=1.9"], "allowed: a number in [2, 100]"),
    (
        ["run", APN, "--set", "guidance.apn.trigger_on=1e-300"],
        "guidance.apn.trigger_on: 1e-300 is out of range; allowed: a number in [0.01, 1e+06]",
    ),
    (["run", APN, "--set", "guidance.apn.trigger_off=0.005"], "guidance.apn.trigger_off: 0.005"),
    (
        ["run", APN, "--set", "spacecraft.mass_kg=0.003"],
        "spacecraft.propellant_kg: 25 kg is not less than spacecraft.mass_kg = 0.003 kg",
    ),
    (
        ["run", APN, "--set", "approach.impactor_position_km=[1.34175e8, 0.4, 0.0]"],
        "approach.impactor_position_km: 400 m from the target's centre; allowed: more than 2",
    ),
    # 1.7e9 km at 10.2 km/s: 5.3 years
    (
        ["run", APN, "--set", "approach.impactor_position_km=[1.34176e8, 1.7e9, 0.0]"],
        "time of flight 1929 days (range / closing speed); allowed: at most 30 days",
    ),
    (["run", APN, "--set", "guidance.coast_s=1e6"], "guidance.coast_s: 1e+06; allowed: (0, "),
    (
        ["run", APN, "--set", "approach.target_position_km=[inf, 0.0, 0.0]"],
        "approach.target_position_km: got inf; allowed: 3 numbers, each in (-inf, inf) km",
    ),
]


@pytest.mark.parametrize("argv,message", BAD_INPUT)
def test_bad_input_is_one_clear_line_before_compilation(argv, message, capsys, monkeypatch):
    def no_compile(*a, **k):
        raise AssertionError("compiled despite bad input")

    monkeypatch.setattr(montecarlo, "_compile", no_compile)
    with pytest.raises(SystemExit) if argv[-2] in ("--runs", "--seed") else _returns(2):
        code = cli.main(argv)
        if code:
            raise SystemExit(code)
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("gnc-jax: error: ")
    assert message in err
    assert "allowed" in err


class _returns:
    def __init__(self, code):
        self.code = code

    def __enter__(self):
        return self

    def __exit__(self, tp, value, tb):
        assert tp is SystemExit and value.code == self.code
        return True


def test_api_errors_name_the_field():
    sc = gj.load_scenario("deep-impact-los")
    with pytest.raises(ScenarioError, match=r"^runs: 0; allowed"):
        gj.run_study(sc, runs=0)
    with pytest.raises(ScenarioError, match=r"^seed: -1"):
        gj.run_study(sc, runs=1, seed=-1)
    with pytest.raises(ScenarioError, match=r"guidance.predictive.burn_times_s"):
        sc.with_overrides(
            {"guidance.law": "predictive", "guidance.predictive.burn_times_s": [1200.0, 1205.0]}
        )
    # the LOS law has no burn times: a schedule it does not fly is not checked against it
    sc.with_overrides({"camera.image_interval_s": 30.0, "guidance.dt_s": 1.0})
    # a single override string is not a list of overrides (its characters are not fields)
    with pytest.raises(ScenarioError, match=r"^overrides: the single string 'guidance.los.k1=3'"):
        gj.load_scenario("deep-impact-los", overrides="guidance.los.k1=3")
    with pytest.raises(ScenarioError, match=r"^overrides: 3; allowed"):
        sc.with_overrides([3])


def test_a_field_range_reads_as_it_is_enforced():
    """An unbounded end is printed open (inf itself is refused); counts agree in number."""
    one = Field("floats", [0.0], lo=0.0, length=1, units="km")
    assert one.allowed() == "1 number, each in [0, inf) km"
    assert Field("float", 0.0).allowed() == "a number in (-inf, inf)"
    with pytest.raises(ScenarioError, match=r"^x: got inf; allowed: 1 number, each in \[0, inf\)"):
        one.check("x", [math.inf])
    with pytest.raises(ScenarioError, match=r"^x: expected 1 number, got 2"):
        one.check("x", [1.0, 2.0])
    assert one.check("x", [1e308]) == [1e308]


def test_user_toml_and_resolved_round_trip(tmp_path):
    sc = gj.load_scenario(
        "deep-impact-predictive", overrides=["guidance.predictive.tolerance_m=0.5"]
    )
    path = tmp_path / "mine.toml"
    path.write_text(sc.to_toml())
    again = gj.load_scenario(path)
    assert again.config == sc.config
    assert again.paper == sc.paper and again.runs == sc.runs
    assert again["guidance.predictive.tolerance_m"] == 0.5
    # defaults fill fields a user file leaves out
    small = tmp_path / "small.toml"
    small.write_text('[scenario]\nname = "x"\nkind = "impactor"\n[guidance.los]\nk1 = 3.0\n')
    s2 = gj.load_scenario(small)
    assert s2["guidance.los.k1"] == 3.0 and s2["spacecraft.thrust_n"] == 88.0
    assert s2["guidance.law"] == "los" and "predictive" not in s2.config["guidance"]


def test_list(capsys):
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    assert "deep-impact-los" in out and "deep-impact-predictive" in out
    assert cli.main(["list", "--fields"]) == 0
    assert "guidance.los.k1 = 4.0" in capsys.readouterr().out


def test_run_writes_results_and_report(tmp_path, capsys):
    out = tmp_path / "los"
    # 4 runs on every device: the program of the impactor's family tests and of
    # test_reproduce_side_by_side
    argv = [
        "run",
        "deep-impact-los",
        "--runs",
        "4",
        "--seed",
        "2",
        "--out",
        str(out),
        "--no-progress",
    ] + [x for s in SHORT for x in ("--set", s)]
    assert cli.main(argv) == 0
    printed = capsys.readouterr().out
    assert "miss_rms_m" in printed and "paper vs gnc_jax" in printed
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "scenario",
        "runs",
        "failed",
        "seed",
        "wall_s",
        "compile_s",
        "miss_rms_m",
        "miss_mean_m",
        "miss_max_m",
        "dv_mean_mps",
        "dv_max_mps",
        "firings_max",
        "firings_mode",
    ):
        assert key in summary, key
    table = pq.read_table(out / "runs")
    assert table.num_rows == 4
    miss = table.column("miss_m").to_numpy()
    assert summary["miss_rms_m"] == pytest.approx(np.sqrt(np.mean(miss**2)))
    assert set(table.column("status_name").to_pylist()) == {"ok"}
    assert "delivery_error_m_0" in table.column_names
    resolved = gj.load_scenario(out / "scenario.toml")
    assert resolved["approach.position_km"] == [9180.0, 0.0, 0.0]

    assert cli.main(["report", str(out)]) == 0
    for name in ("b_plane.png", "dv_firings.png", "engine_trace.png", "centroid_frames.png"):
        png = out / name
        assert png.is_file() and png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000


def test_report_of_missing_dir_is_an_error(tmp_path, capsys):
    assert cli.main(["report", str(tmp_path / "nothing")]) == 2
    assert "nothing: no such directory" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert cli.main(["report", str(tmp_path / "empty")]) == 2
    assert "summary.json: missing" in capsys.readouterr().err


@pytest.mark.parametrize(
    "name,message",
    [
        ("cells.parquet", "an envelope's directory (cells.parquet)"),
        ("training.json", "a tuning's directory (training.json)"),
    ],
)
def test_report_of_another_commands_output_says_what_it_is(name, message, tmp_path, capsys):
    (tmp_path / name).write_text("")
    assert cli.main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "allowed" in err and len(err.splitlines()) == 1
    assert cli.main(["report", str(tmp_path / name)]) == 2
    assert f"{name}: a file, not a directory" in capsys.readouterr().err


def test_reproduce_side_by_side(tmp_path, capsys, monkeypatch):
    short = {
        name: gj.load_scenario(name, overrides=SHORT)
        for name in ("deep-impact-los", "deep-impact-predictive")
    }
    monkeypatch.setattr("gnc_jax.reproduction.list_scenarios", lambda: list(short.values()))
    assert cli.main(["reproduce", "--out", str(tmp_path), "--runs", "4", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "miss RMS (m)" in out and "148.8" in out and "90.1" in out
    md = (tmp_path / "reproduce.md").read_text()
    assert "| `deep-impact-los` | 4 | miss RMS (m) | 90.1 |" in md
    assert pathlib.Path(tmp_path / "deep-impact-predictive" / "summary.json").is_file()


def test_pn_run_writes_results_and_report(tmp_path, capsys):
    out = tmp_path / "apn"
    short = [
        "approach.impactor_position_km=[1.3417501e8, 20400.0, 0.0]",
        "guidance.coast_s=60.0",
        "navigation.knowledge_position_km=[2.0, 0.2, 0.2]",
    ]
    argv = ["run", "bennu-apn", "--runs", "4", "--out", str(out), "--no-progress"]
    assert cli.main(argv + [x for s in short for x in ("--set", s)]) == 0
    printed = capsys.readouterr().out
    assert "miss_rms_m" in printed and "paper vs gnc_jax" in printed and "83.4" in printed
    summary = json.loads((out / "summary.json").read_text())
    for key in ("miss_rms_m", "miss_max_m", "dv_mean_mps", "firings_mean", "ignitions_mean"):
        assert key in summary, key
    table = pq.read_table(out / "runs")
    assert {"miss_t_m", "miss_r_m", "dv_mps", "firings", "status_name"} <= set(table.column_names)
    assert cli.main(["report", str(out)]) == 0
    for name in ("command_trace.png", "command_laws.png", "b_plane.png", "dv_firings.png"):
        png = out / name
        assert png.is_file() and png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000


@pytest.mark.parametrize("name", [n for n in gj.scenario.packaged_names() if n.startswith("bennu")])
def test_pn_scenarios_load_with_paper_rows(name):
    sc = gj.load_scenario(name)
    assert sc.kind == "intercept" and sc.paper
    for key in sc.paper:
        assert key in sc.system.paper_labels, key


def test_a_renamed_kind_says_its_new_name(tmp_path):
    old = tmp_path / "old.toml"
    old.write_text('[scenario]\nname = "x"\nkind = "pn"\n')
    with pytest.raises(ScenarioError, match=r"scenario.kind: 'pn' \(renamed 'intercept'\)"):
        gj.load_scenario(old)


def test_an_unwritable_out_dir_is_refused_before_compilation(capsys, monkeypatch):
    def no_compile(*a, **k):
        raise AssertionError("compiled despite an unwritable --out")

    monkeypatch.setattr(montecarlo, "_compile", no_compile)
    assert cli.main(["run", "deep-impact-los", "--runs", "5", "--out", "/dev/null/study"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("gnc-jax: error: --out /dev/null/study: cannot create or write")
    assert cli.main(["reproduce", "--out", "/dev/null/r", "--runs", "1"]) == 2
    assert "--out /dev/null/r" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "deep-impact-los", "--max-hours", "1e-9"],
        ["tune", "deep-impact-los", "--params", "guidance.los.nosuch"],
        ["envelope", "deep-impact-los", "--grid", "guidance.los.k1=-1,2", "--runs", "4"],
        ["budget", "deep-impact-los", "--metrics", "nosuch"],
        ["reproduce", "--only", "deep-impact-los", "--max-hours", "1e-9"],
    ],
)
def test_a_refused_command_leaves_no_out_dir_it_created(argv, tmp_path, capsys, monkeypatch):
    def no_compile(*a, **k):
        raise AssertionError("compiled despite bad input")

    monkeypatch.setattr(montecarlo, "_compile", no_compile)
    out = tmp_path / "new" / "out"
    assert cli.main([*argv, "--out", str(out)]) == 2
    assert "allowed" in capsys.readouterr().err
    assert not out.exists()
    (tmp_path / "kept").mkdir()  # a directory that was there stays
    assert cli.main([*argv, "--out", str(tmp_path / "kept")]) == 2
    assert (tmp_path / "kept").is_dir()


def test_reproduce_of_an_unknown_scenario_is_refused(capsys, tmp_path):
    assert cli.main(["reproduce", "--out", str(tmp_path), "--only", "nosuch"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gnc-jax: error: --only nosuch: unknown scenario; allowed: ")
    assert not (tmp_path / "reproduce.md").exists()


def test_usage_errors_name_the_command_once(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main([])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().endswith("(see gnc-jax --help)")
    with pytest.raises(SystemExit):
        cli.main(["run"])
    assert capsys.readouterr().err.strip().endswith("(see gnc-jax run --help)")


def test_a_study_whose_every_run_failed_exits_3(tmp_path, capsys, monkeypatch):
    system = gj.get_system("toy-intercept")

    class AlwaysNaN(type(system)):
        def simulate(self, params, law, key, record=False):
            out, trace = super().simulate(params, law, key, record)
            return out._replace(miss_m=out.miss_m * float("nan")), trace

    monkeypatch.setattr(montecarlo, "get_system", lambda kind: AlwaysNaN())
    monkeypatch.setattr(study_module, "get_system", lambda kind: AlwaysNaN())
    toy = pathlib.Path(__file__).with_name("toy.toml")
    out = tmp_path / "toy"
    assert cli.main(["run", str(toy), "--runs", "4", "--out", str(out), "--no-progress"]) == 3
    assert "4 of 4 runs failed" in capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed"] == 4 and summary["failed_by_status"] == {"nan": 4}
    assert summary["statistics"].startswith("none: no run is ok")  # not NaN statistics
    assert "miss_rms_m" not in summary


def test_output_piped_to_a_reader_that_stops_is_no_error(monkeypatch, capsys):
    # `gnc-jax list --fields | head -1`: the reader closes the pipe; the command ends quietly
    def closed(args):
        raise BrokenPipeError(32, "Broken pipe")

    parser = cli.build_parser()
    args = parser.parse_args(["list"])
    monkeypatch.setattr(cli, "build_parser", lambda: _Fixed(args, closed))
    assert cli.main(["list"]) == 0
    assert "internal error" not in capsys.readouterr().err


def test_a_failed_study_piped_to_a_reader_that_stops_still_exits_3(tmp_path, monkeypatch):
    # `gnc-jax run ... | head -3`: the summary's lines after the reader stopped are dropped,
    # and the study's runs that failed still decide the exit code
    system = gj.get_system("toy-intercept")

    class AlwaysNaN(type(system)):
        def simulate(self, params, law, key, record=False):
            out, trace = super().simulate(params, law, key, record)
            return out._replace(miss_m=out.miss_m * float("nan")), trace

    class ClosedPipe:
        lines = 0
        fd = os.open(os.devnull, os.O_WRONLY)  # where the command sends the rest

        def fileno(self):
            return self.fd

        def write(self, text):
            self.lines += text.count("\n")
            if self.lines > 3:
                raise BrokenPipeError(32, "Broken pipe")
            return len(text)

        def flush(self):
            pass

    monkeypatch.setattr(montecarlo, "get_system", lambda kind: AlwaysNaN())
    monkeypatch.setattr(study_module, "get_system", lambda kind: AlwaysNaN())
    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    toy = pathlib.Path(__file__).with_name("toy.toml")
    out = tmp_path / "toy"
    try:
        code = cli.main(["run", str(toy), "--runs", "4", "--out", str(out), "--no-progress"])
    finally:
        os.close(ClosedPipe.fd)
    assert code == 3
    assert json.loads((out / "summary.json").read_text())["failed"] == 4


class _Fixed:
    def __init__(self, args, func):
        self.args, self.func = args, func

    def parse_args(self, argv):
        self.args.func = self.func
        return self.args
