"""The chute ranges the reference design reaches, found before it runs, against the nominal
flights near the skip window's edge and the design's own stages."""

import re

import jax.numpy as jnp
import numpy as np
import pytest
from entry_problem import skip_entry_problem

import gnc_jax as gj
from gnc_jax.guidance.entry import cache, design_reach, nominal, reach


def test_a_target_beyond_the_designs_skip_out_is_refused_before_the_design(tmp_path, monkeypatch):
    """The packaged capsule at 12 000 km: inside the hull of every bank pair's chute ranges
    (the reach check, 1802 .. 12 901 km) but beyond what any stage of the design reaches (its
    optimiser's designs end between 11 850 and 11 868 km). The refusal comes before any design
    stage runs, naming the ranges; its far end is where the nominal at FAR_REACH_BANK_RAD skips
    out, against a brute-force scan of first-entry banks near that edge."""

    def design_ran(*_, **__):
        raise AssertionError("the design ran")

    monkeypatch.setenv("GNC_JAX_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "design_with_fallback", design_ran)
    monkeypatch.setattr(cache, "design_at_the_edge", design_ran)
    problem, cfg = skip_entry_problem(["entry.range_km=12000"])
    with pytest.raises(gj.ScenarioError) as e:
        cache.reference_for(problem, {"entry": cfg["entry"], "vehicle": cfg["vehicle"]})
    text = str(e.value)
    assert "\n" not in text
    assert text.startswith(
        "entry.range_km: 12000 km; allowed: a range the reference design reaches with a skip ("
    )
    spans = [
        (float(a), float(b))
        for a, b in re.findall(r"(\d+) \.\. (\d+)", re.search(r"\((.*) km;", text).group(1))
    ]
    # the design's stages put the chute on 2000 km (profile design) and 11 850 km (optimiser)
    assert any(lo <= 2000.0 and 11850.0 <= hi for lo, hi in spans)
    far = spans[-1][1]
    assert far < 12000.0
    # brute force: the longest landing at that bank on a 0.01 deg grid near the window's edge
    banks = np.radians(np.arange(72.5, 73.0, 0.01))
    err, fate = (
        np.asarray(x)[:, 0]
        for x in reach.candidate_flights(
            problem, jnp.asarray(banks), jnp.asarray([design_reach.FAR_REACH_BANK_RAD])
        )
    )
    lands = fate == nominal.SKIP_LANDS
    assert lands.any() and not lands.all()
    longest = 12000.0 + err[lands].max() / 1e3  # within a grid step (60 km) short of the edge
    assert far - 60.0 < longest < far + 1.0
