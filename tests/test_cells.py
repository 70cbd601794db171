"""Several studies in one compiled call (``gnc_jax.cells``): each cell's outcomes are those of
``run_study`` of its scenario, whatever the grouping, the chunking and the padding; a cell
that a study would refuse is refused alone; the envelope gives the same cells either way."""

import pathlib

import numpy as np
import pytest

import gnc_jax as gj
from gnc_jax.cells import run_cells

TOY = str(pathlib.Path(__file__).with_name("toy.toml"))
FAST = {"geometry.range_m": 3000.0, "geometry.dispersion_m": 200.0, "navigation.noise_m": 5.0}


def toy(**extra):
    return gj.load_scenario(TOY, overrides={**FAST, **extra})


def assert_same_runs(batched, alone, system):
    rtol, atol = system.batch_tolerance
    assert batched.outcomes.keys() == alone.outcomes.keys()
    for field, x in alone.outcomes.items():
        y = batched.outcomes[field]
        assert y.shape == x.shape, field
        if np.issubdtype(x.dtype, np.floating):
            np.testing.assert_allclose(y, x, rtol=rtol, atol=atol, err_msg=field)
        else:
            np.testing.assert_array_equal(y, x, err_msg=field)


def test_cells_equal_their_studies_across_groups_chunks_and_padding():
    # two laws: two programs; three pn cells share one; 5 runs in chunks of 2 (the last padded)
    cells = [
        toy(**{"guidance.pn.n": 2.5}),
        toy(**{"guidance.law": "zem"}),
        toy(**{"guidance.pn.n": 3.5, "geometry.lateral_speed_mps": 9.0}),
        toy(**{"guidance.pn.n": 4.5}),
    ]
    studies = run_cells(cells, runs=5, seed=4, chunk_size=2)
    system = cells[0].system
    for cell, study in zip(cells, studies):
        alone = gj.run_study(cell, runs=5, seed=4, progress=False, n_devices=1)
        assert_same_runs(study, alone, system)
        assert study.runs == 5 and study.chunk_size == 2
    # one compilation per program, charged to its first cell
    assert studies[0].compile_s > 0 and studies[1].compile_s > 0
    assert studies[2].compile_s == 0 and studies[3].compile_s == 0
    misses = [s.summary()["miss_rms_m"] for s in studies]
    assert len(set(misses)) == 4  # the cells differ by their values


def test_a_refused_cell_is_refused_alone_and_bad_requests_name_the_argument():
    out = run_cells([toy(), toy()], runs=2, seed=0, max_hours=1e-12)
    assert all(isinstance(s, gj.ScenarioError) for s in out)
    assert "cost" in str(out[0])
    with pytest.raises(gj.ScenarioError, match="runs: 0; allowed"):
        run_cells([toy()], runs=0, seed=0)
    with pytest.raises(gj.ScenarioError, match="chunk_size: 0; allowed"):
        run_cells([toy()], runs=2, seed=0, chunk_size=0)
    other = gj.load_scenario("deep-impact-los")
    with pytest.raises(gj.ScenarioError, match="allowed: one system"):
        run_cells([toy(), other], runs=2, seed=0)


def test_the_envelope_gives_the_same_cells_batched_or_one_by_one():
    grid = ["guidance.pn.n=2.5:4.5:3"]
    one_by_one = gj.envelope(toy(), grid, runs=6, seed=1, progress=False, batch_cells=False)
    batched = gj.envelope(toy(), grid, runs=6, seed=1, progress=False, batch_cells=True)
    assert [c["status"] for c in batched.cells] == ["simulated"] * 3
    for a, b in zip(one_by_one.cells, batched.cells):
        assert a["failed"] == b["failed"]
        for key in one_by_one.metrics:
            if isinstance(a.get(key), float):
                assert b[key] == pytest.approx(a[key], rel=1e-9, abs=1e-9), key
