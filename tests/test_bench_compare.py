"""``python -m benchmarks.compare``: two suite runs matched row by row, each side's best."""

import json
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from benchmarks import compare  # noqa: E402


def _results(path, rows):
    path.write_text(json.dumps({"results": {"scale": {"rows": rows}}}))
    return str(path)


def test_rows_are_matched_by_labels_and_sizes_and_each_side_gives_its_best(tmp_path, capsys):
    row = lambda runs, wall, rate, note="a": dict(  # noqa: E731
        scenario="x", note=note, runs=runs, wall_s=wall, runs_per_s=rate, failed=0
    )
    before = [
        _results(tmp_path / "b1.json", [row(10, 2.0, 5.0), row(20, 1.0, 20.0)]),
        _results(tmp_path / "b2.json", [row(10, 1.0, 10.0)]),  # the best of the two: 1.0
    ]
    after = _results(tmp_path / "a.json", [row(10, 1.5, 8.0), row(20, 0.5, 40.0), row(30, 1, 1)])
    rows = compare.compare(compare.timings(before), compare.timings([after]))
    got = {(label.split("runs=")[1], field): ratio for label, field, _, _, ratio in rows}
    assert got == {
        ("10 scenario=x", "wall_s"): 1.5,  # slower: 1.0 -> 1.5 s
        ("10 scenario=x", "runs_per_s"): 1.25,  # 10 -> 8 runs/s is a time ratio of 1.25
        ("20 scenario=x", "wall_s"): 0.5,
        ("20 scenario=x", "runs_per_s"): 0.5,
    }  # runs=30 has no counterpart; "failed" is no timing
    compare.main([",".join(before), after, "--slower", "1.2"])
    out = capsys.readouterr().out
    assert out.startswith("4 timings matched; 2 slower by 1.2x or more")
    assert "1.50x" in out and "0.50x" not in out
