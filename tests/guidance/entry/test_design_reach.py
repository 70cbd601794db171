"""The chute ranges the reference design reaches, found before it runs, against the nominal
flights near the skip window's edge and the design's own stages."""

import re

import jax.numpy as jnp
import numpy as np
import pytest
from entry_problem import skip_entry_problem

import gnc_jax as gj
from gnc_jax.guidance.entry import cache, design, design_reach, nominal, reach


def test_a_target_beyond_the_designs_skip_out_is_refused_before_the_design(tmp_path, monkeypatch):
    """The packaged capsule at 12 100 km: inside the hull of every bank pair's chute ranges
    (the reach check, 1802 .. 12 901 km) but beyond what any stage of the design reaches (its
    optimiser's designs end between 11 850 and 11 868 km, its far-bank design's where the
    nominal at FAR_REACH_BANK_RAD skips out). The refusal comes before any design stage runs,
    naming the ranges; its far end is that skip-out, against a brute-force scan of first-entry
    banks near that edge."""

    def design_ran(*_, **__):
        raise AssertionError("the design ran")

    monkeypatch.setenv("GNC_JAX_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "design_with_fallback", design_ran)
    monkeypatch.setattr(cache, "design_at_the_edge", design_ran)
    problem, cfg = skip_entry_problem(["entry.range_km=12100"])
    with pytest.raises(gj.ScenarioError) as e:
        cache.reference_for(problem, {"entry": cfg["entry"], "vehicle": cfg["vehicle"]})
    text = str(e.value)
    assert "\n" not in text
    assert text.startswith(
        "entry.range_km: 12100 km; allowed: a range the reference design reaches with a skip ("
    )
    spans = [
        (float(a), float(b))
        for a, b in re.findall(r"(\d+) \.\. (\d+)", re.search(r"\((.*) km;", text).group(1))
    ]
    # the design's stages put the chute on 2000 km (profile design) and 11 850 km (optimiser)
    assert any(lo <= 2000.0 and 11850.0 <= hi for lo, hi in spans)
    far = spans[-1][1]
    assert far < 12100.0
    # brute force: the longest landing at that bank on a 0.005 deg grid near the window's edge
    banks = np.radians(np.arange(72.5, 73.0, 0.005))
    err, fate = (
        np.asarray(x)[:, 0]
        for x in reach.candidate_flights(
            problem, jnp.asarray(banks), jnp.asarray([design_reach.FAR_REACH_BANK_RAD])
        )
    )
    lands = fate == nominal.SKIP_LANDS
    assert lands.any() and not lands.all()
    longest = 12100.0 + err[lands].max() / 1e3  # within a grid step (60 km) short of the edge
    assert far - 60.0 < longest < far + 1.0


def test_a_target_inside_the_reach_beyond_the_optimisers_designs_is_designed(monkeypatch):
    """The packaged capsule at 11 950 km: inside the design reach (1838 .. 12 009 km), beyond
    the optimiser's designs (to 11 850 km; refused at 11 868 km) and the profile design's
    intervals. With the optimiser's stages missing the target (stubbed: its starting point,
    hundreds of km off), the design's last stage puts the chute on it with the constant
    FAR_REACH_BANK_RAD second-entry bank and a first-entry bank inside the skip window; a
    first-entry bank 1e-6 rad either side skips and lands beyond and short of the target."""
    problem, cfg = skip_entry_problem(["entry.range_km=11950"])
    start = design.DesignResult(
        nominal.SIGMA_1_GUESS_RAD, *nominal.PROFILE_INIT_RAD, nominal.V_SWITCH_INIT_MPS, []
    )
    monkeypatch.setattr(design, "design", lambda *_, **__: start)
    monkeypatch.setattr(design, "fine_first_entry_guess", lambda *_, **__: None)
    d = design.design_with_fallback(problem, cfg["entry"], cfg["vehicle"])
    assert d.sigma_a == d.sigma_b == design_reach.FAR_REACH_BANK_RAD
    assert nominal.SIGMA_1_BOUNDS_RAD[0] < d.sigma_1 < nominal.SIGMA_1_BOUNDS_RAD[1]
    flights = [
        nominal.fly_nominal_jit(problem, s1, d.sigma_a, d.sigma_b, d.v_switch)
        for s1 in (d.sigma_1 - 1e-6, d.sigma_1, d.sigma_1 + 1e-6)
    ]
    assert all(int(nominal.fate_of(f)) == nominal.SKIP_LANDS for f in flights)
    err = [float(nominal.range_error_m(problem, f)) for f in flights]
    assert abs(err[1]) < nominal.RANGE_TOLERANCE_M
    assert err[0] > 0.0 > err[2]  # the chute range falls with the bank through the target
