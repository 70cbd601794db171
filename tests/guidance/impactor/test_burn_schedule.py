"""Predictive burn schedules given as times to go scale with the approach;
a schedule outside the guided arc is refused before compilation, an implausibly early last
burn is warned about on the command line and in summary.json."""

import json

import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax import cli, montecarlo
from gnc_jax import study as study_module

TGO = "guidance.predictive.burn_tgo_s=[6000.0, 3100.0, 750.0, 420.0]"


@pytest.mark.parametrize("range_km", [73440.0, 146880.0])
def test_times_to_go_give_mission_times_of_the_approach(range_km):
    sc = gj.load_scenario(
        "deep-impact-predictive", overrides=[TGO, f"approach.position_km=[{range_km}, 0.0, 0.0]"]
    )
    _, law = gj.build(sc)
    tof = range_km / 10.2  # straight line at 10.2 km/s
    np.testing.assert_allclose(
        law.burn_times_s, tof - np.array([6000.0, 3100.0, 750.0, 420.0]), atol=1e-6
    )
    if range_km == 73440.0:  # seed 002's own schedule, written either way
        np.testing.assert_array_equal(
            law.burn_times_s, gj.build(gj.load_scenario("deep-impact-predictive"))[1].burn_times_s
        )


@pytest.mark.parametrize(
    "tgo,message",
    [
        ("[8000.0, 420.0]", "a burn 8000 s before impact is outside the guided arc; allowed: "),
        ("[6000.0, 30.0]", "times to go in (60, 7200] s"),
        ("[420.0, 6000.0]", "allowed: decreasing times to go"),
    ],
)
def test_a_schedule_outside_the_guided_arc_is_one_line_before_compilation(
    tgo, message, capsys, monkeypatch
):
    def no_compile(*a, **k):
        raise AssertionError("compiled despite bad input")

    monkeypatch.setattr(montecarlo, "_compile", no_compile)
    argv = ["run", "deep-impact-predictive", "--set", f"guidance.predictive.burn_tgo_s={tgo}"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("gnc-jax: error: guidance.predictive.burn_tgo_s: ")
    assert message in err


def test_an_early_last_burn_is_warned_and_recorded(capsys):
    """A 900 s approach whose last burn comes 600 s before impact, in the first half of the
    840 s guided arc (one aim point, so no retarget burn is required): warned on stderr and
    kept in the summary (here of a study whose single run is a stand-in: nothing is compiled)."""
    overrides = [
        "approach.position_km=[9180.0, 0.0, 0.0]",
        "guidance.aim_final_km=[0.0, 0.0]",
        "guidance.predictive.burn_tgo_s=[800.0, 600.0]",
    ]
    sc = gj.load_scenario("deep-impact-predictive", overrides=overrides)
    cli._print_warnings(sc)
    err = capsys.readouterr().err
    assert err.startswith("gnc-jax: warning: guidance.predictive.burn_tgo_s: the last burn is at")
    assert "300 s, 600 s before impact" in err and len(err.splitlines()) == 1
    study = study_module.Study(sc, 1, 0, {"status": np.array([gj.Status.nan])}, 0.0, 1.0, 1, 1)
    summary = json.loads(json.dumps(study.summary()))
    assert len(summary["warnings"]) == 1 and "first half" in summary["warnings"][0]
    # the packaged schedule (last burn 420 s before a 7200 s impact) is not warned about
    system = gj.get_system("impactor")
    assert system.warnings(gj.load_scenario("deep-impact-predictive").config) == []
    assert (
        "warnings"
        not in study_module.Study(
            gj.load_scenario("deep-impact-predictive"), 1, 0, study.outcomes, 0.0, 1.0, 1, 1
        ).summary()
    )
