"""Two runs of the suite side by side, row by row: what got slower.

    python -m benchmarks.compare BEFORE.json[,BEFORE2.json] AFTER.json[,AFTER2.json]
        [--slower 1.10] [--all]

Each side is one or more results files of ``python -m benchmarks --out FILE`` (for a
before/after of two trees: the suite run from each, alternating, on the same idle machine).
Rows are matched by their module and their labels (every text field, and the sizes: runs,
steps, arcs, workers, devices, chunk); each timing field of a matched row is compared, the
best of the side's files (the least time, the most throughput), as the time ratio after /
before (above 1: slower). Prints the rows at or above ``--slower`` (``--all``: every row).
Timings of a few milliseconds (the quick sizes) move by tens of per cent between runs of
unchanged code: a peer's rows, measured in the same run, give the noise.
"""

import argparse
import json
import math

TIME_FIELDS = {  # field -> +1: a time (lower is better), -1: a rate (higher is better)
    "wall_s": 1,
    "us_per_run": 1,
    "ms_per_run": 1,
    "cpu_us_per_run": 1,
    "closed_ns": 1,
    "steps_only_ns": 1,
    "bare_ns": 1,
    "ns_per_step": 1,
    "closed_ns_per_control_step": 1,
    "per_s": -1,
    "runs_per_s": -1,
    "arcs_per_s": -1,
    "evals_per_s": -1,
    "rhs_per_s": -1,
    "bare_evals_per_s": -1,
}
SIZE_FIELDS = ("runs", "steps", "arcs", "workers", "devices", "chunk")


def row_label(module: str, row: dict) -> str:
    parts = [module]
    for k, v in sorted(row.items()):
        if isinstance(v, str) or (k in SIZE_FIELDS and v is not None):
            parts.append(f"{k}={v}")
    return " ".join(parts)


def timings(paths) -> dict:
    """``{(row label, field): [values]}`` over the results files ``paths``."""
    out: dict = {}
    for path in paths:
        with open(path) as f:
            results = json.load(f)["results"]
        for module, res in results.items():
            for row in res.get("rows", []):
                for field in TIME_FIELDS:
                    v = row.get(field)
                    if isinstance(v, int | float) and math.isfinite(v) and v > 0:
                        out.setdefault((row_label(module, row), field), []).append(float(v))
    return out


def compare(before: dict, after: dict) -> list[tuple[str, str, float, float, float]]:
    """``(row, field, before, after, time ratio after / before)`` for every matched timing,
    each side's best value."""
    rows = []
    for key in sorted(set(before) & set(after)):
        sign = TIME_FIELDS[key[1]]
        best = min if sign > 0 else max
        b, a = best(before[key]), best(after[key])
        rows.append((*key, b, a, a / b if sign > 0 else b / a))
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before", help="results file(s), comma-separated")
    p.add_argument("after", help="results file(s), comma-separated")
    p.add_argument("--slower", type=float, default=1.10, help="print time ratios from this on")
    p.add_argument("--all", action="store_true", help="print every matched row")
    args = p.parse_args(argv)
    rows = compare(timings(args.before.split(",")), timings(args.after.split(",")))
    shown = [r for r in rows if args.all or r[4] >= args.slower]
    print(f"{len(rows)} timings matched; {sum(r[4] >= args.slower for r in rows)} slower by "
          f"{args.slower:g}x or more")  # fmt: skip
    for label, field, b, a, ratio in shown:
        print(f"{ratio:6.2f}x  {b:11.4g} -> {a:11.4g}  {field:<26} {label}")


if __name__ == "__main__":
    main()
