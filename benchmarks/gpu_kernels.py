"""The deep closed loops on an accelerator: study wall times and kernels per loop trip, this
checkout against a reference checkout, in one call.

    PYTHONPATH=. python benchmarks/gpu_kernels.py [--ref DIR] [--quick] [--out FILE]

Times, through the public API with the CLI's defaults (the planner's chunk, seed 0), compile
apart (``Study.compile_s``; ``Study.wall_s`` is the study after compilation):
``bennu-apn`` 2,000 runs (91,200 strictly sequential steps: latency-bound), ``bennu-apn``
200,000 runs (throughput-bound) and ``deep-impact-los`` 1,000,000 runs. For each study it also
counts, in the optimized HLO of the program that ran, the operations of every loop body
(fusions and copies are kernels on a GPU; transposes and concatenations inside fusions are
where 3-vectors are stacked): the innermost closed-loop body is the figure that makes a loop
shallow.

``--ref DIR``: the same studies with the package of another checkout (e.g. the main branch
extracted with ``git archive main | tar -x -C DIR``) as the baseline, each checkout in its own
process, the two interleaved round by round (best of ``--rounds``); the table shows both and
the ratio reference / this. ``--quick``: a few runs of each on whatever JAX finds (a smoke
test on a CPU).
"""

import argparse
import collections
import json
import os
import pathlib
import re
import subprocess
import sys

HERE = pathlib.Path(__file__).resolve()
ROOT = HERE.parents[1]
STUDIES = [("bennu-apn", 2_000), ("bennu-apn", 200_000), ("deep-impact-los", 1_000_000)]
QUICK = [("bennu-apn", 8), ("deep-impact-los", 64)]
FREE = {"parameter", "get-tuple-element", "tuple", "bitcast", "constant", "after-all"}


def _computations(text: str) -> dict:
    comps, cur = {}, None
    for line in text.splitlines():
        m = re.match(r"^(ENTRY )?%?([\w.\-]+) .*\{\s*$", line)
        if m and not line.startswith(" "):
            cur = m.group(2)
            comps[cur] = []
        elif line.startswith("}"):
            cur = None
        elif cur and line.strip():
            comps[cur].append(line.strip())
    return comps


def _ops(comps, name):
    for line in comps.get(name, []):
        m = re.match(r"(ROOT )?%?([\w.\-]+) = (.*?) ([a-z\-]+)\((.*)$", line)
        if m:
            yield m.group(4), line


def loop_bodies(text: str) -> list[dict]:
    """Every ``while`` body of an optimized HLO module: its trip count and its operations by
    kind (``in-fusion transpose``/``concatenate``: inside its fusions)."""
    comps, rows = _computations(text), []

    def walk(name, depth):
        count = collections.Counter()
        for op, line in _ops(comps, name):
            if op in FREE:
                continue
            count[op] += 1
            if op == "while":
                body = re.search(r"body=%?([\w.\-]+)", line).group(1)
                trip = re.search(r"known_trip_count=\{n=(\d+)", line) or re.search(
                    r'"n":"(\d+)"', line
                )
                inner = walk(body, depth + 1)
                rows.append(dict(depth=depth, trip=trip and int(trip.group(1)), ops=inner))
            elif op == "fusion":
                called = re.search(r"calls=%?([\w.\-]+)", line)
                for sub, _ in _ops(comps, called.group(1) if called else ""):
                    if sub in ("transpose", "concatenate"):
                        count[f"in-fusion {sub}"] += 1
        return dict(count)

    entry = next(
        line.split()[1].lstrip("%") for line in text.splitlines() if line.startswith("ENTRY")
    )
    walk(entry, 0)
    return rows


def child(args) -> None:
    """One checkout's measurements, in this process: ``args.json`` gets one row per study."""
    import gnc_jax as gj
    from gnc_jax import montecarlo

    rows = []
    for name, runs in QUICK if args.quick else STUDIES:
        scenario = gj.load_scenario(name)
        montecarlo._COMPILED.clear()
        kw = dict(runs=runs, seed=0, progress=False, max_hours=1e6)
        first = gj.run_study(scenario, **kw)
        second = gj.run_study(scenario, **kw)  # compiled: the wall time alone
        bodies = [
            dict(b, kernels=sum(v for k, v in b["ops"].items() if not k.startswith("in-")))
            for c in montecarlo._COMPILED.values()
            for b in loop_bodies(c.as_text())
            if b["trip"] != 5  # the threefry hash's own loop
        ]
        rows.append(
            dict(
                scenario=name,
                runs=runs,
                chunk=first.chunk_size,
                compile_s=round(first.compile_s, 3),
                wall_s=round(min(first.wall_s, second.wall_s), 4),
                failed=first.summary()["failed"],
                loops=bodies,
            )
        )
        print(f"  {name} {runs}: wall {rows[-1]['wall_s']} s", flush=True)
    pathlib.Path(args.json).write_text(json.dumps(rows, indent=1))


def _run(package: pathlib.Path, args, tag: str, round_: int) -> list[dict]:
    out = pathlib.Path(args.out).with_suffix(f".{tag}{round_}.json")
    cmd = [sys.executable, str(HERE), "--child", "--json", str(out)]
    cmd += ["--quick"] if args.quick else []
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(filter(None, [str(package), os.environ.get("PYTHONPATH", "")])),
    )
    subprocess.run(cmd, env=env, check=True, cwd=package)
    return json.loads(out.read_text())


def _innermost(row) -> str:
    loops = [b for b in row["loops"] if b["trip"]]
    if not loops:
        return "-"
    deepest = max(loops, key=lambda b: (b["depth"], b["kernels"]))
    ops = deepest["ops"]
    return (
        f"{deepest['kernels']} ({ops.get('copy', 0)} copies, "
        f"{ops.get('in-fusion transpose', 0)}+{ops.get('transpose', 0)} transposes)"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--ref", default="", help="another checkout: the baseline")
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default="gpu_kernels.json")
    p.add_argument("--child", action="store_true")
    p.add_argument("--json", default="")
    args = p.parse_args()
    if args.child:
        return child(args)
    this, ref = {}, {}
    for r in range(args.rounds):  # interleaved: the two checkouts share the machine's drift
        if args.ref:
            for row in _run(pathlib.Path(args.ref).resolve(), args, "ref", r):
                key = (row["scenario"], row["runs"])
                if key not in ref or row["wall_s"] < ref[key]["wall_s"]:
                    ref[key] = row
        for row in _run(ROOT, args, "this", r):
            key = (row["scenario"], row["runs"])
            if key not in this or row["wall_s"] < this[key]["wall_s"]:
                this[key] = row
    pathlib.Path(args.out).write_text(
        json.dumps(dict(this=list(this.values()), ref=list(ref.values())), indent=1)
    )
    print(f"{'study':28s} {'wall s':>8s} {'ref s':>8s} {'ratio':>6s}  innermost body: this | ref")
    for key, row in this.items():
        base = ref.get(key)
        ratio = f"{base['wall_s'] / row['wall_s']:.2f}" if base else "-"
        print(
            f"{key[0] + ' ' + str(key[1]):28s} {row['wall_s']:8.3f} "
            f"{base['wall_s'] if base else float('nan'):8.3f} {ratio:>6s}  "
            f"{_innermost(row)} | {_innermost(base) if base else '-'}"
        )


if __name__ == "__main__":
    main()
