"""The capsule law and the capsule's load limit: the direct mode's load relief (its rule against
the exponential atmosphere's closed form, and the far end of the direct reach, where dispersed
runs dive in a second dip beyond the limit without it), and the predictions' load margin (a
prediction loaded beyond a fraction of the limit is a dive), which keeps the corrector's
plans within it."""

import types

import numpy as np

import gnc_jax as gj
from gnc_jax._status import Status
from gnc_jax.dynamics.atmosphere import Atmosphere
from gnc_jax.guidance.entry.phases import load_relief
from gnc_jax.guidance.entry.predictor import dive_load_g


def _law(relief="direct", fraction=0.95, lead_s=10.0, limit_g=10.0, direct=True):
    return types.SimpleNamespace(
        direct=direct,
        load_relief=relief,
        load_relief_fraction=fraction,
        load_relief_lead_s=lead_s,
        load_limit_g=limit_g,
    )


def test_the_relief_rule_against_the_exponential_closed_form():
    """In an exponential atmosphere the load a sink rate Hdot brings in the lead time tau is
    ng exp(-Hdot tau / H): the direct entry's rule relieves exactly where that exceeds the
    fraction of the limit, after the pull-up only, and for a climb on the load itself."""
    h_scale = 7200.0
    atmosphere = Atmosphere(model="exponential", scale_height_m=h_scale)
    rng = np.random.default_rng(0)
    ng = rng.uniform(0.0, 12.0, 400)
    hdot = rng.uniform(-600.0, 300.0, 400)
    altitude = rng.uniform(20e3, 70e3, 400)
    pulled = rng.uniform(size=400) < 0.7
    law = _law(lead_s=12.0, limit_g=9.0)
    density = atmosphere.density(altitude)
    got = np.asarray(load_relief(law, pulled, ng, altitude, hdot, atmosphere, density))
    ahead = ng * np.exp(-np.minimum(hdot, 0.0) * 12.0 / h_scale)
    margin = np.abs(ahead - 0.95 * 9.0) > 1e-9  # away from the boundary's last bits
    want = pulled & (ahead > 0.95 * 9.0)
    np.testing.assert_array_equal(got[margin], want[margin])
    assert want.sum() > 50 and (~want & pulled).sum() > 50
    # a climb: the load now alone; the lead 0: the load now
    rho = atmosphere.density(40e3)
    climb = np.asarray(load_relief(_law(), True, 9.6, 40e3, 50.0, atmosphere))
    lead0 = np.asarray(load_relief(_law(lead_s=0.0), True, 9.4, 40e3, -400.0, atmosphere, rho))
    assert climb and not lead0
    # off, or a skip: no relief, compiled out
    for law in (_law("off"), _law(direct=False)):
        assert load_relief(law, pulled, ng, altitude, hdot, atmosphere, density) is None


def test_the_relief_keeps_far_direct_entries_within_the_load_limit():
    """-5.9 deg / 3000 km, a direct entry near the far end of its reach: without the relief
    some of 32 dispersed runs dive in their second dip beyond 10 g and read overload; with
    it every run lands within the delivery tolerance below the limit."""
    sc = gj.load_scenario("lunar-skip-entry", overrides=["entry.range_km=3000"])
    off = gj.run_study(
        sc.with_overrides(["guidance.skip_entry.load_relief=off"]), runs=32, progress=False
    )
    overloaded = off.status == Status.overload
    assert overloaded.sum() >= 1
    on = gj.run_study(sc, runs=32, progress=False)
    assert (on.status == Status.ok).all()
    limit = sc.config["simulation"]["load_limit_g"]
    assert on.outcomes["load_peak_g"].max() < limit < off.outcomes["load_peak_g"].max()
    # the runs flew the direct mode: no switch point
    assert (on.outcomes["switch_speed_mps"] == 0.0).all()


def test_the_dive_load_is_the_guard_or_the_fraction_of_the_limit_below_it():
    def law(limit_g, fraction=0.9, direct=False):
        return types.SimpleNamespace(
            predictor_dive_load_g=20.0,
            predictor_load_fraction=fraction,
            load_limit_g=limit_g,
            direct=direct,
        )

    assert float(dive_load_g(law(10.0))) == 0.9 * 10.0
    assert float(dive_load_g(law(np.inf))) == 20.0  # a mission without a limit: the guard
    assert float(dive_load_g(law(10.0, fraction=2.5))) == 20.0
    assert float(dive_load_g(law(40.0))) == 20.0
    assert float(dive_load_g(law(10.0, direct=True))) == 20.0  # a direct entry: the guard


def test_the_predictions_keep_a_margin_to_a_lower_load_limit():
    """The packaged skip (-5.9 deg / 8000 km) of a capsule limited to 5.3 g, within the
    nominal's 5.6 g largest peak: with its predictions allowed up to twice the limit
    (``predictor_load_fraction`` 2) the corrector plans loads beyond it and some of 32
    dispersed runs read ``overload``; with predictions ending as dives beyond 90 % of it every
    run lands ``ok`` below 95 % of the limit."""
    sc = gj.load_scenario("lunar-skip-entry", overrides=["simulation.load_limit_g=5.3"])
    # in chunks of four on every device: the program tests/test_family.py compiles (the limit
    # and the fraction are leaves of it)
    study = dict(runs=32, chunk_size=4, progress=False)
    loose = gj.run_study(
        sc.with_overrides(["guidance.skip_entry.predictor_load_fraction=2"]), **study
    )
    assert (loose.status == Status.overload).sum() >= 1
    margin = gj.run_study(sc, **study)
    assert (margin.status == Status.ok).all()
    assert margin.outcomes["load_peak_g"].max() < 0.95 * 5.3 < loose.outcomes["load_peak_g"].max()
